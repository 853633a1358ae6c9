"""The ``[sensor]`` model extensions (vignetting, camera response, stray light, colour matrix):
exact at their null values, equal to their closed forms, derivatives equal to finite differences, and read,
validated and written back through the scene file."""

from __future__ import annotations

import re

import mitsuba as mi
import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.errors import SceneError
from abs.model.downsampling import downsample_camera
from abs.render import Camera, PathTracer, compile_scene
from abs.render.sensor import radial_moments
from abs.scene import load_scene, write_scene
from conftest import assert_same_rendering
from gradcheck import assert_gradients_agree, directional_gradient

W = H = 24
SPP = 8


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.08, 0.32]), np.array([0.0, 0.05, 0.0]))
    K = intrinsics_from_fov(W, H, np.radians(40))
    K[0, 2] += 1.5  # off-centre principal point: the falloff must centre on it
    camera = Camera(K, R, t, W, H)
    weights = mi.TensorXf(np.random.default_rng(0).uniform(0, 1, (H, W, 3)).astype(np.float32))
    return compiled, camera, weights


def _radiance(compiled, camera, seed=3):
    """The path tracer's image with no sensor applied."""
    return PathTracer(max_depth=4).render(compiled.mitsuba_scene, compiled.environment, camera,
                                          SPP, seed).numpy()


def _reset(compiled):
    compiled.set("sensor.vignetting", [0.0, 0.0])
    compiled.set("sensor.response", [1.0, 1.0, 1.0])
    compiled.set("sensor.stray_light", [0.0, 0.0, 0.0])
    compiled.set("sensor.colour_matrix", np.eye(3).ravel())


#: A colour matrix near the identity, with cross-talk of both signs (rendering RGB -> photograph).
_MATRIX = np.array([[1.06, 0.03, -0.02], [0.04, 0.95, 0.01], [-0.03, 0.05, 1.08]])


def test_null_sensor_is_identity(setup):
    compiled, camera, _ = setup
    _reset(compiled)
    for cam in (camera, downsample_camera(Camera(camera.K, camera.R, camera.t, 2 * W, 2 * H), 2)):
        rendered = compiled.render(cam, spp=SPP, seed=3, max_depth=4).numpy()
        assert_same_rendering(rendered, _radiance(compiled, cam))


def test_identity_colour_matrix_is_bitwise_the_identity():
    """The same image through the sensor: at M = I each pixel comes back bit for bit (zeros and
    values spanning many octaves included), with the matrix stored like any fitted value."""
    from abs.render.sensor import Sensor

    image = np.random.default_rng(1).lognormal(-2.0, 3.0, (H, W, 3)).astype(np.float32)
    image[:3] = 0.0
    camera = Camera(intrinsics_from_fov(W, H, np.radians(40)), np.eye(3), np.zeros(3), W, H)
    sensor = Sensor([0.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], np.eye(3).ravel())
    out = sensor.apply(mi.TensorXf(image), camera).numpy()
    assert np.array_equal(out.view(np.uint32), image.view(np.uint32))


def test_sensor_closed_form(setup):
    compiled, camera, _ = setup
    k, gamma, offset = [-0.4, 0.2], [0.8, 1.0, 1.3], [0.01, 0.02, 0.0]
    compiled.set("sensor.vignetting", k)
    compiled.set("sensor.response", gamma)
    compiled.set("sensor.stray_light", offset)
    compiled.set("sensor.colour_matrix", _MATRIX.ravel())
    try:
        rendered = compiled.render(camera, spp=SPP, seed=3, max_depth=4).numpy()
    finally:
        _reset(compiled)
    # r from the pixel centre's OpenCV normalised coordinates, directly.
    v, u = np.mgrid[0:H, 0:W]
    x = (u - camera.K[0, 2]) / camera.K[0, 0]
    y = (v - camera.K[1, 2]) / camera.K[1, 1]
    r2 = (x * x + y * y)[..., None]
    # The colour matrix mixes the veiled linear signal, before the response (docs/scene-format.md).
    veiled = (1 + k[0] * r2 + k[1] * r2 ** 2) * _radiance(compiled, camera) + offset
    expected = np.einsum("ij,hwj->hwi", _MATRIX, veiled) ** np.array(gamma)
    np.testing.assert_allclose(rendered, expected, rtol=2e-5, atol=1e-7)


def test_radial_moments_average_fine_pixels(setup):
    _, camera, _ = setup
    fine = Camera(camera.K, camera.R, camera.t, 2 * W, 2 * H)
    coarse = downsample_camera(fine, 2)
    r2_fine, r4_fine = radial_moments(fine)
    r2, r4 = radial_moments(coarse)
    np.testing.assert_allclose(r2, r2_fine.reshape(H, 2, W, 2).mean(axis=(1, 3)), rtol=1e-10)
    np.testing.assert_allclose(r4, r4_fine.reshape(H, 2, W, 2).mean(axis=(1, 3)), rtol=1e-10)


@pytest.mark.parametrize("name, value, direction, h", [
    ("sensor.vignetting", [0.0, 0.0], [1.0, 0.5], 0.05),
    ("sensor.vignetting", [-0.3, 0.1], [1.0, -0.5], 0.05),
    ("sensor.response", [1.0, 1.0, 1.0], [1.0, 0.5, 0.7], 0.02),
    ("sensor.response", [0.7, 1.2, 1.5], [1.0, 0.5, 0.7], 0.02),
    ("sensor.stray_light", [0.0, 0.0, 0.0], [1.0, 0.3, 0.6], 0.005),
    ("sensor.stray_light", [0.05, 0.02, 0.01], [1.0, 0.3, 0.6], 0.005),
    # Every entry moved at once, off-diagonal ones with both signs.
    ("sensor.colour_matrix", np.eye(3).ravel(), [1.0, 0.5, -0.7, 0.4, -1.0, 0.6, -0.3, 0.8, 0.9], 0.02),
    ("sensor.colour_matrix", _MATRIX.ravel(), [1.0, 0.5, -0.7, 0.4, -1.0, 0.6, -0.3, 0.8, 0.9], 0.02),
])
def test_sensor_gradient(setup, name, value, direction, h):
    """At the null value (what a score test sees) and away from it."""
    compiled, camera, weights = setup
    compiled.set(name, value)
    try:
        res = directional_gradient(compiled, camera, name, direction, h, weights, seeds=3, spp=4 * SPP,
                                   full=True)
    finally:
        _reset(compiled)
    assert_gradients_agree(*res, rel=0.02)


def test_sensor_fields_round_trip_and_errors(small_scene_dir, tmp_path):
    scene = load_scene(small_scene_dir / "scene.toml")
    values = {"sensor.vignetting": [-0.2, 0.05], "sensor.response": [0.9, 1.0, 1.1],
              "sensor.stray_light": [0.01, 0.0, 0.02], "sensor.colour_matrix": _MATRIX.ravel().tolist()}
    again = load_scene(write_scene(scene, tmp_path / "written" / "scene.toml", values))
    for name, value in values.items():
        np.testing.assert_allclose(getattr(again.sensor, name.split(".")[1]), value)

    text = (small_scene_dir / "scene.toml").read_text()
    for table, message in [('[sensor]\nresponse = [1.0, 0.1, 1.0]', "sensor.response: all entries must be >= 0.2"),
                           ('[sensor]\nstray_light = -0.1', "sensor.stray_light: all entries must be >= 0"),
                           ('[sensor]\nvignetting = [0.1]', "sensor.vignetting: expected shape [2]"),
                           ('[sensor]\ngamma = 2.2', "sensor.gamma: unknown field"),
                           ('[sensor]\ncolour_matrix = 1.0', "sensor.colour_matrix: expected 9 numbers"),
                           ('[sensor]\ncolour_matrix = [1.0, 0.0, 0.0, 1.0]', "sensor.colour_matrix: expected 9 numbers"),
                           ('[sensor]\ncolour_matrix = [[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]',
                            "sensor.colour_matrix: expected shape [3, 3]"),
                           ('[sensor]\ncolour_matrix = [1, 0, 0, 0, "1", 0, 0, 0, 1]',
                            "sensor.colour_matrix: expected numbers of shape [9]")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace("[materials.glass]", table + "\n\n[materials.glass]"))
        for asset in ("sphere.ply", "floor.ply", "backdrop.obj", "env.exr", "checker.png"):
            (tmp_path / asset).write_bytes((small_scene_dir / asset).read_bytes())
        with pytest.raises(SceneError, match=re.escape(message)) as info:
            load_scene(bad)
        assert str(bad) in str(info.value)


def test_fit_recovers_a_white_balance_matrix(tmp_path):
    """Photographs with a 5500 K white-balance error made by colour-science's Bradford adaptation
    (not abs's sensor); a fit of ``sensor.colour_matrix`` from the identity finds that matrix.
    The checkerboard is coloured (red, green, blue, grey cells): under grey light a grey scene
    only shows each row's sum."""
    import cv2

    from abs.fitting import FitSettings, fit
    from abs.render.sensor_truth import white_balance_matrix, white_balance_shift
    from abs.simulate import simulate_capture
    from conftest import make_backdrop, make_env, make_sphere_and_floor, sphere_scene_toml

    make_sphere_and_floor(tmp_path)
    make_backdrop(tmp_path)
    make_env(tmp_path / "env.exr")
    v, u = np.mgrid[0:64, 0:64]
    cells = np.array([[60, 60, 230], [60, 200, 60], [230, 60, 60], [200, 200, 200]], np.uint8)  # BGR
    cv2.imwrite(str(tmp_path / "checker.png"), cells[((u // 8) + 2 * (v // 8)) % 4])
    (tmp_path / "scene.toml").write_text(sphere_scene_toml(["sensor.colour_matrix"], absorption=[2.0, 4.0, 8.0]))
    scene = load_scene(tmp_path / "scene.toml")

    def photograph(compiled, camera, spp, seed):
        return white_balance_shift(compiled.render(camera, spp=spp, seed=seed).numpy(), 5500)

    simulate_capture(scene, tmp_path / "capture", n_cameras=3, width=32, height=24, spp=64,
                     read_noise=0.003, seed=2, render=photograph)
    result = fit(scene, tmp_path / "capture",
                 settings=FitSettings(spp=8, downsample=1, max_iterations=4, refinement_steps=0))
    truth = white_balance_matrix(5500).ravel()
    fitted = result.values["sensor.colour_matrix"]
    stderr = result.vector.split(result.uncertainty.stderr)["sensor.colour_matrix"]
    # Measured: within 0.025 of the truth (about one standard error, ~0.03) from an identity
    # 0.16 away (the blue gain).
    assert np.abs(fitted - np.eye(3).ravel()).max() > 0.15
    assert np.all(np.abs(fitted - truth) < 3 * stderr + 0.005), (fitted - truth, stderr)
    assert np.abs(fitted - truth).max() < 0.05
