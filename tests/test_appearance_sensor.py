"""abs.appearance's per-pixel steps: the sensor step (vignetting, colour matrix, response) and
the ratio form of the λ shift, on closed-form and synthetic cases; the block means in the file.

Small and fast: the sensor fits run on synthetic block means, and the renders are 32 pixels.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs.appearance import characterise, read_characterisation, renderer, transfer, write_characterisation
from abs.appearance.design import characterisation_design
from abs.appearance.renderers import camera_response
from abs.appearance.scenes import design_camera, scene_geometry
from abs.appearance.sensor import (BLOCK_GRID, Sensor, block_means, block_radius2, fit_sensor,
                                   image_radius2)
from abs.appearance.statistics import Accumulator
from abs.appearance.transfer import SHIFTS, sensor_step
from abs.errors import InputError

# A camera the fit never sees: vignetting 1 - 0.3 r² + 0.05 r⁴, a matrix whose rows sum to 1
# (the model's convention: the level belongs to the response), a compressive response.
VIGNETTING = np.array([-0.3, 0.05])
MATRIX = np.array([[0.8, 0.15, 0.05], [0.1, 0.85, 0.05], [0.0, 0.2, 0.8]])


def _true_sensor(x: np.ndarray, r2: np.ndarray) -> np.ndarray:
    y = x * (1.0 + VIGNETTING[0] * r2 + VIGNETTING[1] * r2 ** 2)[..., None]
    return camera_response(y @ MATRIX.T, knee=1.2, power=0.85, black=0.0)


@pytest.fixture(scope="module")
def synthetic_blocks():
    """Block means of 12 "scenes": colours log-uniform over 2.5 decades, independent per block
    and channel (so every image position sees many colours), and their images through the
    known camera, evaluated at each block's centre (no Monte-Carlo noise, no edges)."""
    rng = np.random.default_rng(4)
    a = 10.0 ** rng.uniform(-2.0, 0.5, size=(12, BLOCK_GRID, BLOCK_GRID, 3))
    b = _true_sensor(a, np.broadcast_to(block_radius2(), a.shape[:3]))
    return a, b


def test_sensor_fit_recovers_a_known_camera(synthetic_blocks):
    a, b = synthetic_blocks
    s = fit_sensor(a, b)
    np.testing.assert_allclose(s.matrix, MATRIX, atol=0.01)
    # The vignetting gain itself (what the coefficients trade between them) within 1 % to the corner.
    r2 = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(1 + s.vignetting[0] * r2 + s.vignetting[1] * r2 ** 2,
                               1 + VIGNETTING[0] * r2 + VIGNETTING[1] * r2 ** 2, rtol=0.01)
    # The response, over the radiance the blocks covered, within 2 % (piecewise log-linear
    # knots against a smooth curve).
    x = np.repeat(np.logspace(-1.8, 0.3, 30)[:, None], 3, axis=1)
    np.testing.assert_allclose(s.curve(x), camera_response(x, 1.2, 0.85, 0.0), rtol=0.02)
    # And a whole new image: pixel positions as the transfer uses them.
    rng = np.random.default_rng(9)
    image = 10.0 ** rng.uniform(-1.5, 0.2, size=(24, 32, 3))
    np.testing.assert_allclose(s.apply(image), _true_sensor(image, image_radius2(24, 32)), rtol=0.02)


def test_sensor_fit_of_a_renderer_onto_itself_is_the_identity(synthetic_blocks):
    a, _ = synthetic_blocks
    s = fit_sensor(a, a)
    np.testing.assert_allclose(s.matrix, np.eye(3), atol=1e-3)
    np.testing.assert_allclose(s.vignetting, 0.0, atol=1e-3)
    x = np.repeat(np.logspace(-1.8, 0.3, 12)[:, None], 3, axis=1)
    np.testing.assert_allclose(s.curve(x), x, rtol=2e-3)


def test_sensor_fit_refuses_too_little_or_mismatched_data(synthetic_blocks):
    a, b = synthetic_blocks
    with pytest.raises(InputError, match="shape"):
        fit_sensor(a, b[:3])
    with pytest.raises(InputError, match="bright enough"):
        fit_sensor(a[:1] * 1e-4, b[:1] * 1e-4)


def test_block_means_and_radius():
    image = np.zeros((32, 32, 3))
    image[:16, :16] = 1.0  # the top-left quarter: 8x8 blocks of a 16-grid at 2 pixels a block
    m = block_means(image)
    assert m.shape == (BLOCK_GRID, BLOCK_GRID, 3)
    assert (m[:8, :8] == 1).all() and (m[8:] == 0).all() and (m[:, 8:] == 0).all()
    assert np.isnan(block_means(np.ones((8, 8, 3)))).any()  # a grid finer than the image
    r2 = image_radius2(32, 32)
    assert r2.min() < 0.01 and 0.9 < r2.max() <= 1.0
    np.testing.assert_allclose(block_means(r2[..., None].repeat(3, -1))[..., 0], block_radius2(), atol=0.01)


# -- the λ shift ------------------------------------------------------------------------------

def _theta_filtered_pair():
    """A textured "renderer A" (pixels spread widely within each θ bin, as a metal's do) and
    B = A · (1 + 0.8 cos θ): the characterisation of both, and a held-out image of each."""
    cam = design_camera(32)
    design = characterisation_design(1, classes=("metal",), walls=("red", "white"))
    rng = np.random.default_rng(2)

    def textured(geo):
        base = np.where(geo.ids[..., None] > 0, 0.3, 0.2) * np.array([1.0, 0.8, 0.6])
        return base * 10.0 ** rng.uniform(-1.0, 0.7, size=geo.ids.shape + (3,))

    def filtered(img, geo):
        return img * np.where(geo.ids > 0, 1.0 + 0.8 * np.cos(np.nan_to_num(geo.theta)), 1.0)[..., None]

    acc_a, acc_b = Accumulator(("metal",), 6), Accumulator(("metal",), 6)
    for spec in design:
        geo = scene_geometry(spec, cam)
        img = textured(geo)
        light = np.ones_like(img)
        acc_a.add(img, geo, light)
        acc_b.add(filtered(img, geo), geo, light)
    geo = scene_geometry(design[0], cam)
    image = textured(geo)
    return acc_a.finish("a", {}, "d", {}), acc_b.finish("b", {}, "d", {}), image, filtered(image, geo), geo


def test_ratio_shift_is_exact_for_a_theta_filter_and_never_negative():
    """A filter that multiplies by a function of θ: the ratio form moves each pixel by its bin's
    factor (up to the filter's variation inside a 15° bin); the additive form shifts the dark
    pixels as far as the bright ones, so the darkest tenth ends up tens of per cent off."""
    a, b, image, target, geo = _theta_filtered_pair()
    on = geo.ids > 0
    ratio = transfer(image, geo, a, b, shift="ratio")
    additive = transfer(image, geo, a, b, shift="additive")
    assert (ratio[on] >= 0).all()
    rel = np.abs(ratio[on] / target[on] - 1)
    assert np.median(rel) < 0.03 and rel.max() < 0.15  # (1 + 0.8 cos θ) varies ≤ 15 % in a bin
    dark = target[on] < np.percentile(target[on], 10)
    rel_add = np.abs(additive[on] / target[on] - 1)
    assert np.median(rel_add[dark]) > 0.2 > 0.03 > np.median(rel[dark])
    assert set(SHIFTS) == {"ratio", "additive"}
    with pytest.raises(InputError):
        transfer(image, geo, a, b, shift="bogus")


# -- the sensor step in the transfer, and the file -------------------------------------------

@pytest.fixture(scope="module")
def camera_pair():
    """abs and a known camera (`camera` renderer: vignetting, matrix, response) characterised on
    a small design at 32 pixels, and a new image by each."""
    env = np.full((32, 64, 3), 0.8, np.float32) * np.array([1.0, 0.9, 0.8], np.float32)
    design = characterisation_design(1, classes=("wood", "plastic"))
    kw = {"size": 32, "spp": 16, "n_bins": 6}
    a = characterise(renderer("abs"), design, env, seed=0, **kw)
    b = characterise(renderer("camera"), design, env, seed=0, **kw)  # same seed: same noise
    spec = characterisation_design(1, classes=("wood",), walls=("white",))[0]
    cam = design_camera(32)
    return (a, b, renderer("abs").render(spec, env, cam, 16, 5),
            renderer("camera").render(spec, env, cam, 16, 5), scene_geometry(spec, cam))


def test_sensor_step_undoes_the_simulated_camera(camera_pair):
    """Rendered with one seed by abs and by the camera, the images differ only by the camera:
    the sensor step, fitted on 8 scenes' block means, reproduces it to a few per cent on a new
    image (block means of a 32-pixel image straddle edges; the fit is robust to them)."""
    a, b, image, target, geo = camera_pair
    s = sensor_step(a, b)
    before = np.abs(image / target - 1)
    after = np.abs(transfer(image, geo, a, b, sensor=s, theta=False) / target - 1)
    bright = target.min(-1) > 0.02
    assert np.median(after[bright]) < 0.03 < np.median(before[bright])
    np.testing.assert_allclose(s.matrix, renderer("camera").options["colour_matrix"], atol=0.05)
    # With the θ transfer after it (A's statistics carried through the sensor): still close.
    both = np.abs(transfer(image, geo, a, b, sensor=s) / target - 1)
    assert np.median(both[bright & (geo.ids > 0)]) < 0.05


def test_block_means_in_the_file_and_files_without_them(camera_pair, tmp_path):
    a, b = camera_pair[:2]
    assert a.blocks.shape == (len(a.profiles), BLOCK_GRID, BLOCK_GRID, 3)
    write_characterisation(tmp_path / "a.npz", a)
    np.testing.assert_array_equal(read_characterisation(tmp_path / "a.npz").blocks, a.blocks)
    # A file from before the sensor step (no blocks) still reads; the sensor step says why not.
    data = dict(np.load(tmp_path / "a.npz", allow_pickle=False))
    data.pop("blocks")
    np.savez(tmp_path / "old.npz", **data)
    old = read_characterisation(tmp_path / "old.npz")
    assert old.blocks is None
    with pytest.raises(InputError) as err:
        sensor_step(old, b)
    assert err.value.field == "blocks" and "again" in str(err.value)
    for bad in (np.full(a.blocks.shape, np.inf), a.blocks[:, :4], a.blocks[:2], a.blocks[..., :2]):
        data["blocks"] = bad
        np.savez(tmp_path / "bad.npz", **data)
        with pytest.raises(InputError) as err:
            read_characterisation(tmp_path / "bad.npz")
        assert err.value.field == "blocks" and "bad.npz" in str(err.value)


def test_cli_transfer_with_the_sensor_step(tmp_path):
    """Gains rendered with abs's own seed are exactly abs's image times the gains, so the sensor
    step fitted through the command line must give back that image times the gains."""
    from abs.cli.main import main
    from abs.io.images import read_image

    gains = np.array([1.5, 1.0, 0.7])
    common = ["--classes", "wood", "--walls", "white,red", "--samples", "1", "--size", "32",
              "--spp", "4", "--environment", "constant:0.7"]
    assert main(["appearance", "characterise", "--renderer", "abs", "--out", str(tmp_path / "a"),
                 *common]) == 0
    assert main(["appearance", "characterise", "--renderer", "gains", "--option", f"gains={gains.tolist()}",
                 "--out", str(tmp_path / "b"), *common]) == 0
    scene = tmp_path / "a" / "scenes" / "wood-0-white"
    image = read_image(scene / "image.exr")
    args = [str(scene / "image.exr"), "--geometry", str(scene / "geometry.npz"),
            "--from", str(tmp_path / "a" / "characterisation.npz"),
            "--to", str(tmp_path / "b" / "characterisation.npz")]
    bright = image.min(-1) > 0.02
    for name, extra in (("both", ["--sensor", "--normals"]), ("alone", ["--method", "sensor"]),
                        ("additive", ["--shift", "additive"])):
        out = tmp_path / f"{name}.exr"
        assert main(["appearance", "transfer", *args, "--out", str(out), *extra]) == 0
        summary = json.loads(out.with_suffix(".json").read_text())
        result = read_image(out)
        if name == "alone":
            np.testing.assert_allclose(result[bright], (image * gains)[bright], rtol=0.02)
            # The summary's sensor is the fitted one: rebuilt from the JSON it gives the image back.
            j = summary["sensor"]
            rebuilt = Sensor(*(np.array(j[k]) for k in ("vignetting", "matrix", "knots_log10",
                                                        "response_log10")))
            np.testing.assert_allclose(rebuilt.apply(image), result, rtol=1e-5, atol=1e-7)
        if name != "additive":
            s = summary["sensor"]
            assert np.abs(np.array(s["matrix"]) - np.eye(3)).max() < 0.02
        else:
            assert summary["sensor"] is None and summary["shift"] == "additive"
        assert summary["normals"] == (name == "both")
        assert (summary["normal_step"] is not None) == (name == "both")
    # The steps belong to the statistics method: asking for them with another is an error.
    assert main(["appearance", "transfer", *args, "--out", str(tmp_path / "x.exr"), "--method",
                 "sensor", "--normals"]) == 2
