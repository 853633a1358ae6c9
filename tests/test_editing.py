"""Image-based material editing (abs.editing): each formula of the Khan et al. (2006) baseline
against values worked out by hand, the input errors, and one small `abs edit` run.

The expected numbers are written out (with their arithmetic) rather than recomputed with the
formula under test, so that a wrong formula fails.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs.editing import EditSettings, edit, parse_material
from abs.editing.brdf_replace import shade_with_brdf, tangent_frames
from abs.editing.checks import check_mask, check_photograph, looks_clipped
from abs.editing.depth import (depth_from_luminance, inverse_sigmoid, log_average_luminance,
                               sigmoid)
from abs.editing.environment import (direction_to_photo_pixel, environment_from_photograph,
                                     latlong_directions, latlong_lookup, photo_pixel_to_direction)
from abs.editing.gloss import gloss_curve, remap_gloss
from abs.editing.gradients import forward_differences, normals_from_gradients, reshape_gradients
from abs.editing.highlights import highlight_layer, highlight_threshold
from abs.editing.holes import fill_background
from abs.editing.spec import MaterialSpec
from abs.editing.transparency import (darken, lab_ruderman_to_rgb, rgb_to_lab_ruderman,
                                      transfer_colour)
from abs.errors import InputError
from abs.io.merl import MERL_SHAPE


def synthetic_photo(h: int = 24, w: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """A small HDR "photograph": a shaded, highlighted sphere in front of a smooth background."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    background = np.stack([0.2 + 0.6 * xs / w, 0.3 + 0.4 * ys / h, 0.5 + 0.1 * np.sin(xs / 3)], -1)
    background[2:5, 20:26] = [8.0, 7.0, 6.0]  # a bright window: the image is HDR
    r = 0.3 * min(h, w)
    dx, dy = (xs - (w - 1) / 2) / r, (ys - (h - 1) / 2) / r
    mask = dx ** 2 + dy ** 2 < 1
    n = np.stack([dx, dy, -np.sqrt(np.clip(1 - dx ** 2 - dy ** 2, 0, 1))], -1)
    light = np.array([-0.4, -0.5, -0.77]) / np.linalg.norm([-0.4, -0.5, -0.77])
    half = (light + [0, 0, -1]) / np.linalg.norm(light + [0, 0, -1])
    shade = (0.1 + np.clip(n @ light, 0, None))[..., None] * [0.6, 0.3, 0.2]
    obj = shade + 20 * np.clip(n @ half, 0, None)[..., None] ** 60
    return np.where(mask[..., None], obj, background).astype(np.float32), mask


# ----------------------------------------------------------------------------------- depth

def test_sigmoid_by_hand_and_at_sigma():
    # 4^0.73 = exp(0.73 ln 4) = exp(1.011987) = 2.751084; 2.751084 / 3.751084 = 0.733410.
    assert sigmoid(np.array(4.0), 1.0) == pytest.approx(0.733410, abs=1e-6)
    # L = sigma gives 1/2 whatever n and sigma.
    assert sigmoid(np.array([3.0]), 3.0, n=0.9)[0] == pytest.approx(0.5)


def test_inverse_sigmoid_by_hand_and_round_trip():
    # d = 0.8, sigma = 1: (0.8 / 0.2)^(1 / 0.73) = 4^1.369863 = 6.679435.
    assert inverse_sigmoid(np.array(0.8), 1.0) == pytest.approx(6.679435, rel=1e-6)
    assert inverse_sigmoid(np.array(0.5), 2.0) == pytest.approx(2.0)
    lum = np.array([1e-3, 0.2, 1.0, 7.5, 300.0])
    np.testing.assert_allclose(inverse_sigmoid(sigmoid(lum, 0.4), 0.4), lum, rtol=1e-9)


def test_log_average_luminance_is_the_geometric_mean_of_the_object():
    lum = np.array([[1.0, 4.0, 1000.0]])
    mask = np.array([[True, True, False]])
    assert log_average_luminance(lum, mask) == pytest.approx(2.0, rel=1e-5)  # sqrt(1 * 4)


def test_depth_is_larger_where_brighter_and_zero_off_the_object():
    photo, mask = synthetic_photo()
    depth = depth_from_luminance(photo, mask, relief=1.0)
    assert np.all(depth[~mask] == 0)
    radius = np.sqrt(mask.sum() / np.pi)
    assert depth[mask].max() == pytest.approx(radius)      # scaled to the equivalent radius
    lum = photo @ [0.2126, 0.7152, 0.0722]
    bright, dark = np.unravel_index(np.argmax(np.where(mask, lum, -1)), lum.shape), \
        np.unravel_index(np.argmin(np.where(mask, lum, np.inf)), lum.shape)
    assert depth[bright] > depth[dark]


# ------------------------------------------------------------------------------- gradients

def test_normals_of_depth_ramps():
    ys, xs = np.mgrid[0:4, 0:5].astype(float)
    gx, gy = forward_differences(0.5 * xs)
    np.testing.assert_allclose(gx[:, :-1], 0.5)
    assert np.all(gx[:, -1] == 0) and np.all(gy == 0)
    # n = (-0.5, 0, -1) / sqrt(1.25): faces the camera, tilted left (the surface rises rightwards).
    np.testing.assert_allclose(normals_from_gradients(gx, gy)[1, 1], [-0.447214, 0.0, -0.894427],
                               atol=1e-6)
    gx, gy = forward_differences(-2.0 * ys)
    # n = (0, 2, -1) / sqrt(5)
    np.testing.assert_allclose(normals_from_gradients(gx, gy)[1, 1], [0.0, 0.894427, -0.447214],
                               atol=1e-6)
    flat = normals_from_gradients(np.zeros((2, 2)), np.zeros((2, 2)))
    np.testing.assert_allclose(flat[0, 0], [0, 0, -1])


def test_forward_differences_stop_at_the_mask():
    depth = np.array([[0.0, 1.0, 3.0, 6.0]])
    mask = np.array([[True, True, True, False]])
    gx, _ = forward_differences(depth, mask)
    np.testing.assert_allclose(gx, [[1.0, 2.0, 0.0, 0.0]])


def test_reshaping_spline_at_its_knots_keeps_directions():
    gx = np.array([0.1, 0.0, 0.6])
    gy = np.array([0.0, -0.5, 0.8])   # magnitudes 0.1, 0.5, 1.0 (max 1)
    rx, ry = reshape_gradients(gx, gy, times=1)
    np.testing.assert_allclose(np.hypot(rx, ry), [0.2, 0.55, 1.4], atol=1e-12)
    np.testing.assert_allclose(rx[2] / ry[2], 0.6 / 0.8)
    same = reshape_gradients(gx, gy, times=0)
    np.testing.assert_allclose(same[0], gx)
    twice = np.hypot(*reshape_gradients(gx, gy, times=2))
    assert twice[0] / twice[2] > 0.2 / 1.4      # small gradients boosted again


# ------------------------------------------------------------------------------ background

def test_hole_filling_by_hand():
    row = np.array([[1.0, 2.0, 0.0, 0.0, 0.0, 6.0, 7.0]])
    image = np.repeat(row, 3, axis=0)
    mask = np.zeros((3, 7), bool)
    mask[1, 2:5] = True              # x_min = 1, x_max = 5, width 7
    filled = fill_background(image, mask)
    # x = 2: 0.75 L(0) + 0.25 L(8 mod 7 = 1) = 0.75 + 0.5 = 1.25
    # x = 3: 0.5 L(-1 mod 7 = 6) + 0.5 L(7 mod 7 = 0) = 3.5 + 0.5 = 4
    # x = 4: 0.25 L(-2 mod 7 = 5) + 0.75 L(6) = 1.5 + 5.25 = 6.75
    np.testing.assert_allclose(filled[1], [1.0, 2.0, 1.25, 4.0, 6.75, 6.0, 7.0])
    np.testing.assert_array_equal(filled[[0, 2]], image[[0, 2]])


def test_hole_filling_drops_copies_that_land_on_the_object():
    image = np.array([[1.0, 0.0, 0.0, 0.0, 0.0, 9.0]])
    mask = np.array([[False, True, True, True, True, False]])   # x_min = 0, x_max = 5
    filled = fill_background(image[..., None].repeat(3, axis=2), mask)[..., 0]
    # x = 1: left 2*0 - 1 = -1 -> 5 (9), right 10 - 1 = 9 -> 3 (object: dropped): 9
    # x = 2: left -2 -> 4 (object), right 8 -> 2 (object): nearest background, column 0: 1
    # x = 3: left -3 -> 3 (object), right 7 -> 1 (object): nearest background, column 5
    #        (|5 - 3| = 2 < |0 - 3| = 3): 9
    # x = 4: left -4 -> 2 (object), right 6 -> 0 (1): 1
    np.testing.assert_allclose(filled[0], [1.0, 9.0, 1.0, 9.0, 1.0, 9.0])


# ----------------------------------------------------------------------------- environment

def test_hemisphere_mapping_of_specific_pixels():
    h, w = 5, 9                       # centre (4, 2), radius min(9, 5) / 2 = 2.5
    d = photo_pixel_to_direction(np.array([4.0, 6.5, 5.25, 4.0]), np.array([2.0, 2.0, 2.0, 0.75]),
                                 h, w)
    s = np.sqrt(0.5)
    np.testing.assert_allclose(d, [[0, 0, 1], [1, 0, 0], [s, 0, s], [0, -s, s]], atol=1e-12)
    x, y = direction_to_photo_pixel(np.array([[s, 0, s], [s, 0, -s], [0, 0, -1]]), h, w)
    np.testing.assert_allclose(x, [5.25, 5.25, 4.0])       # the front hemisphere is mirrored
    np.testing.assert_allclose(y, [2.0, 2.0, 2.0])


def test_latlong_map_from_a_coordinate_photograph():
    h, w = 5, 9
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    photo = np.stack([xs, ys, np.zeros_like(xs)], axis=-1)
    env = environment_from_photograph(photo, width=10)     # 5 x 10 map
    assert env.shape == (5, 10, 3)
    # Row 2: theta = pi/2 (horizon); column 3: phi = 2 pi 3.5 / 10 = 0.7 pi.
    # World d = (sin 0.7pi, 0, -cos 0.7pi) = (0.809017, 0, 0.587785); camera (-0.809017, 0,
    # 0.587785); x_n = -0.809017 / (0.809017 + 0.587785) = -0.579192; x = 4 - 2.5 * 0.579192.
    assert env[2, 3, 0] == pytest.approx(2.552020, abs=1e-4)
    assert env[2, 3, 1] == pytest.approx(2.0, abs=1e-5)
    np.testing.assert_allclose(latlong_directions(5, 10)[2, 3], [0.809017, 0.0, 0.587785], atol=1e-6)
    # The map's top row is the zenith: the photograph's top edge (row 0 at the circle, y = 2 - 2.5).
    assert env[0, 0, 1] == pytest.approx(0.0, abs=1e-5)     # clamped to the first row


def test_latlong_lookup_returns_pixel_values_at_their_centres():
    rng = np.random.default_rng(1)
    env = rng.random((6, 12, 3)).astype(np.float32)
    d = latlong_directions(6, 12)
    # Rows 0 and 5 are the poles: one direction for the whole row, so they are left out.
    np.testing.assert_allclose(latlong_lookup(env, d[1:-1]), env[1:-1], atol=1e-5)


# ------------------------------------------------------------------------- highlights, gloss

def test_highlight_threshold_at_the_steepest_fall_of_the_histogram():
    lum = np.array([0.5] * 10 + [1.5] * 8 + [2.5, 3.5])
    # 4 bins on [0, 3.5]: edges 0, 0.875, 1.75, 2.625, 3.5; counts 10, 8, 1, 1;
    # differences -2, -7, 0: minimum after bin 1, threshold = edge 2 = 1.75.
    assert highlight_threshold(lum, bins=4) == pytest.approx(1.75)


def test_highlight_layer_is_the_excess_over_the_threshold():
    rgb = np.full((1, 2, 3), 3.0, np.float32)
    rgb[0, 1] = 0.5
    layer = highlight_layer(rgb, np.ones((1, 2), bool), threshold=1.0)
    np.testing.assert_allclose(layer[0, 0], [2.0, 2.0, 2.0], rtol=1e-5)   # 3 (1 - 1/3)
    np.testing.assert_allclose(layer[0, 1], 0.0)


def test_gloss_curves_at_specific_luminances():
    assert gloss_curve(np.array([0.0, 1.0]), 0.05, 20.0) == pytest.approx([0.0, 1.0])
    # (0.55^20 - 0.05^20) / (1.05^20 - 0.05^20) = 6.41589e-6 / 2.653298 = 2.41806e-6
    assert gloss_curve(np.array(0.5), 0.05, 20.0) == pytest.approx(2.41806e-6, rel=1e-4)
    # (0.55^0.05 - 0.05^0.05) / (1.05^0.05 - 0.05^0.05) = (0.970550 - 0.860891) / 0.141551
    assert gloss_curve(np.array(0.5), 0.05, 0.05) == pytest.approx(0.774696, abs=1e-5)


def test_remap_gloss_on_grey_pixels():
    grey = np.array([0.5, 2.0, 3.0], np.float32)          # luminance = grey value
    rgb = np.repeat(grey[None, :, None], 3, axis=2)
    mask = np.ones((1, 3), bool)
    out = remap_gloss(rgb, mask, threshold=1.0, alpha=0.05, beta=0.05)
    # L = 2: x = (2 - 1) / (3 - 1) = 0.5, L' = 1 + 2 * 0.774696 = 2.549392
    np.testing.assert_allclose(out[0, :, 1], [0.5, 2.549392, 3.0], rtol=1e-5)
    glossier = remap_gloss(rgb, mask, threshold=1.0, alpha=0.05, beta=20.0)
    assert glossier[0, 1, 0] == pytest.approx(1.0 + 2 * 2.41806e-6, rel=1e-5)


# --------------------------------------------------------------------- glass and translucency

def test_dark_glass_power_law():
    rgb = np.array([[[0.5, 1.0, 0.25]]], np.float32)
    out = darken(rgb, np.ones((1, 1), bool), a=1.3)
    # C_max = 1: 0.5^1.3 = 0.406126, 0.25^1.3 = 0.164938
    np.testing.assert_allclose(out[0, 0], [0.406126, 1.0, 0.164938], rtol=1e-5)


def test_colour_transfer_moves_the_chromatic_statistics_only():
    rng = np.random.default_rng(0)
    target = rng.uniform(0.2, 1.0, (200, 3))
    source = rng.uniform(0.2, 1.0, (50, 3)) * [1.0, 0.4, 0.2]   # orange
    np.testing.assert_allclose(lab_ruderman_to_rgb(rgb_to_lab_ruderman(target)), target, rtol=1e-9)
    out = transfer_colour(target, source)
    lab_out, lab_src, lab_tgt = (rgb_to_lab_ruderman(a) for a in (out, source, target))
    np.testing.assert_allclose(lab_out[:, 1:].mean(0), lab_src[:, 1:].mean(0), atol=1e-5)
    np.testing.assert_allclose(lab_out[:, 1:].std(0), lab_src[:, 1:].std(0), rtol=1e-4)
    np.testing.assert_allclose(lab_out[:, 0], lab_tgt[:, 0], atol=1e-5)


# ----------------------------------------------------------------------------- BRDF shading

def test_tangent_frames_are_orthonormal_and_right_handed():
    n = np.array([[0, 0, -1.0], [0.6, 0.0, -0.8], [0.0, 0.0, 1.0]])
    t, b = tangent_frames(n)
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-12)
    np.testing.assert_allclose(np.sum(t * n, -1), 0, atol=1e-12)


def test_lambertian_table_under_a_constant_environment():
    # f = 0.3 / pi everywhere, L_env = 2: L_o = f L_env pi = 0.6 for every normal facing the camera.
    table = np.full(MERL_SHAPE, 0.3 / np.pi, np.float32)
    env = np.full((16, 32, 3), 2.0, np.float32)
    normals = np.zeros((3, 3, 3))
    normals[...] = [0.0, 0.0, -1.0]
    normals[1, 2] = [0.6, 0.0, -0.8]
    mask = np.zeros((3, 3), bool)
    mask[1, 1:] = True
    out = shade_with_brdf(normals, mask, env, table, samples=400, seed=3)
    np.testing.assert_allclose(out[1, 1:], 0.6, rtol=0.03)
    assert np.all(out[~mask] == 0)


# --------------------------------------------------------------------------- grammar, errors

def test_material_grammar():
    assert parse_material("glass") == MaterialSpec("glass", "clear")
    assert parse_material("Glass:Frosted") == MaterialSpec("glass", "frosted")
    assert parse_material("merl:blue-rubber") == MaterialSpec("merl", "blue-rubber")
    assert parse_material("texture:a:b.exr") == MaterialSpec("texture", "a:b.exr")
    assert str(parse_material("glossier")) == "glossier"
    for bad, words in [("metal", "unknown material"), ("glass:blue", "unknown glass"),
                       ("merl", "needs"), ("diffuse:2", "no argument"), ("", "empty")]:
        with pytest.raises(InputError, match=words):
            parse_material(bad)


def test_ldr_photographs_are_refused(tmp_path):
    from abs.io.images import write_png

    photo, mask = synthetic_photo()
    png = tmp_path / "photo.png"
    write_png(png, photo)
    with pytest.raises(InputError, match=r"photo.png: format: .*needs a linear HDR photograph"):
        edit(png, mask, "glass")
    clipped = np.clip(photo, 0, 1)
    assert looks_clipped(clipped) and not looks_clipped(photo)
    with pytest.raises(InputError, match=r"pixels: values stop at 1.0.*HDR"):
        check_photograph(clipped)
    scaled = photo / photo.max()          # HDR normalised to a peak of 1: one pixel at 1, no plateau
    check_photograph(scaled)


def test_bad_masks_are_refused(tmp_path):
    from abs.io.images import write_exr, write_mask

    photo, mask = synthetic_photo()
    path = tmp_path / "mask.png"
    write_mask(path, mask[:-1])
    exr = tmp_path / "photo.exr"
    write_exr(exr, photo)
    with pytest.raises(InputError, match=r"mask.png: size: mask is 32x23 pixels but the photograph "
                                         r"is 32x24"):
        edit(exr, path, "glass")
    with pytest.raises(InputError, match=r"pixels: the mask is empty"):
        check_mask(np.zeros(mask.shape), photo.shape)
    touching = mask.copy()
    touching[5:8, 0] = True
    with pytest.raises(InputError, match=r"touches the image border \(left\)"):
        edit(photo, touching, "glass")


def test_an_unknown_method_is_refused_naming_the_known_ones():
    photo, mask = synthetic_photo()
    with pytest.raises(InputError, match=r"method: unknown method 'magic'; expected one of "
                                         r"baseline, .*synthesis"):
        edit(photo, mask, "glass", method="magic")


# ------------------------------------------------------------------------------- end to end

@pytest.mark.parametrize("material", ["glossier", "diffuse", "glass:clear", "glass:frosted",
                                      "glass:tinted", "glass:dark", "translucent"])
def test_edits_change_only_the_object(material):
    photo, mask = synthetic_photo()
    result = edit(photo, mask, material)
    assert result.image.shape == photo.shape and np.all(np.isfinite(result.image))
    np.testing.assert_array_equal(result.image[~mask], photo[~mask])
    assert np.abs(result.image[mask] - photo[mask]).max() > 0.05
    assert result.environment.shape == (128, 256, 3)


def test_merl_edit_with_the_shared_fits():
    from abs.brdf.nbrdf import nbrdf_archive_path

    if not nbrdf_archive_path().is_file():
        pytest.skip("../shared/data/merl_nbrdf is absent: no MERL materials to edit with")
    photo, mask = synthetic_photo()
    result = edit(photo, mask, "merl:blue-rubber", settings=EditSettings(samples=64))
    np.testing.assert_array_equal(result.image[~mask], photo[~mask])
    body = result.image[mask]
    assert np.all(np.isfinite(body)) and body.mean() > 0
    assert body[:, 2].mean() > body[:, 0].mean()            # blue rubber is blue


def test_a_given_highlight_threshold_replaces_the_histograms():
    photo, mask = synthetic_photo()
    result = edit(photo, mask, "glass", settings=EditSettings(highlight_threshold=1e9))
    assert result.highlight_threshold == 1e9 and not result.highlights.any()


def test_texture_edit_shows_the_texture():
    photo, mask = synthetic_photo()
    stripes = np.zeros((8, 8, 3), np.float32)
    stripes[:, ::2] = [1.0, 0.0, 0.0]
    result = edit(photo, mask, "texture:stripes", texture=stripes,
                  settings=EditSettings(texture_blend=0.0))
    body = mask & ~result.highlights
    red, green = result.image[body, 0], result.image[body, 1]
    assert red.max() > 0.1 and green.max() < 1e-6          # only the texture's red shows


def test_cli_edit_writes_the_results(tmp_path):
    from abs.cli.main import main
    from abs.io.images import read_image, write_exr, write_mask

    photo, mask = synthetic_photo()
    write_exr(tmp_path / "photo.exr", photo)
    write_mask(tmp_path / "mask.png", mask)
    out = tmp_path / "out"
    rc = main(["edit", str(tmp_path / "photo.exr"), "--mask", str(tmp_path / "mask.png"),
               "--to", "glass:tinted", "--out", str(out)])
    assert rc == 0
    edited = read_image(out / "edited.exr")
    np.testing.assert_array_equal(edited[~mask], photo[~mask])
    assert read_image(out / "environment.exr").shape == (128, 256, 3)
    summary = json.loads((out / "edit.json").read_text())
    assert summary["material"] == "glass:tinted" and summary["object_pixels"] == int(mask.sum())
    assert main(["edit", str(tmp_path / "photo.exr"), "--mask", str(tmp_path / "mask.png"),
                 "--to", "gold", "--out", str(out)]) == 2
