"""Colour-chart calibration (abs.colour.chart, .correction, .correction_file, `abs colour`)."""

from __future__ import annotations

import json

import colour
import numpy as np
import pytest

from abs.colour.chart import (check_patches, patch_centres, patch_rgb_from_corners,
                              reference_white_xyz, reference_xyz)
from abs.colour.correction import calibrate, delta_e00, expand, xyz_to_output_matrix
from abs.colour.correction_file import read_correction, write_correction
from abs.errors import InputError

# A camera whose RGB is a linear map of XYZ (a made-up, well-conditioned sensor).
XYZ_TO_CAMERA = np.array([[0.9, 0.3, 0.05], [0.2, 1.0, 0.1], [0.05, 0.2, 0.9]])


def _camera_rgb(xyz):
    return xyz @ XYZ_TO_CAMERA.T


def test_reference_chart_white_patch_is_d50_neutral():
    xyz, white = reference_xyz(), reference_white_xyz()
    assert xyz.shape == (24, 3)
    # Patch 19 (white 9.5) is neutral: its chromaticity is D50's within 0.01.
    np.testing.assert_allclose(colour.XYZ_to_xy(xyz[18]), colour.XYZ_to_xy(white), atol=0.01)
    np.testing.assert_allclose(white[1], 1.0)


def test_root_polynomial_terms_and_exposure_invariance():
    np.testing.assert_allclose(expand([4.0, 9.0, 16.0], 2), [4, 9, 16, 6, 12, 8])
    xyz, white = reference_xyz(), reference_white_xyz()
    rng = np.random.default_rng(0)
    rgb = _camera_rgb(xyz) * (1 + 0.02 * rng.standard_normal(xyz.shape))
    c = calibrate(rgb, xyz, white, degree=2, refine=False)
    # Every root-polynomial term is of degree 1: doubling the exposure doubles XYZ exactly.
    np.testing.assert_allclose(c.to_xyz(2 * rgb), 2 * c.to_xyz(rgb), rtol=1e-12)


def test_linear_camera_is_recovered_exactly():
    xyz, white = reference_xyz(), reference_white_xyz()
    c = calibrate(_camera_rgb(xyz), xyz, white, degree=1, refine=False)
    np.testing.assert_allclose(c.matrix, np.linalg.inv(XYZ_TO_CAMERA), atol=1e-10)
    assert c.delta_e_before.max() < 1e-6


def test_delta_e_refinement_lowers_mean_delta_e_on_a_nonlinear_camera():
    xyz, white = reference_xyz(), reference_white_xyz()
    rgb = _camera_rgb(xyz) ** 1.15  # a sensor the models cannot fit exactly
    c = calibrate(rgb, xyz, white, degree=2, refine=True)
    assert c.delta_e_before.mean() > 0.3
    assert c.delta_e_after.mean() < 0.9 * c.delta_e_before.mean()


def test_delta_e00_known_pair():
    # Sharma, Wu & Dalal (2005) test data, pair 1: Lab (50, 2.6772, -79.7751) vs
    # (50, 0, -82.7485): dE00 = 2.0425. Build XYZ from these Lab under D50.
    white = reference_white_xyz()
    xy = colour.XYZ_to_xy(white)
    a = colour.Lab_to_XYZ([50, 2.6772, -79.7751], xy)
    b = colour.Lab_to_XYZ([50, 0.0, -82.7485], xy)
    np.testing.assert_allclose(delta_e00(a[None], b[None], white), [2.0425], atol=1e-4)


def test_output_space_maps_d50_white_to_equal_cie_rgb_and_known_primaries():
    white = reference_white_xyz()
    m = xyz_to_output_matrix(white, "CIE RGB")
    np.testing.assert_allclose(m @ white, [1.0, 1.0, 1.0], atol=1e-6)
    # Without adaptation (white E), CIE RGB's primary 700 nm is XYZ chromaticity (0.7347, 0.2653).
    m_e = xyz_to_output_matrix(colour.xy_to_XYZ([1 / 3, 1 / 3]), "CIE RGB")
    red = np.linalg.inv(m_e)[:, 0]
    np.testing.assert_allclose(colour.XYZ_to_xy(red), [0.7347, 0.2653], atol=2e-4)


def test_patches_from_corner_points_of_a_synthetic_photograph():
    xyz = reference_xyz()
    rgb = _camera_rgb(xyz)
    image = np.zeros((48, 64, 3))
    # Patch pitch 9 px, patch 1 centred at (8, 8): 4 rows x 6 columns.
    for i in range(24):
        r, c = divmod(i, 6)
        image[8 + 9 * r - 3:8 + 9 * r + 4, 8 + 9 * c - 3:8 + 9 * c + 4] = rgb[i]
    corners = np.array([[8, 8], [53, 8], [53, 35], [8, 35]], float)
    np.testing.assert_allclose(patch_centres(corners)[7], [17, 17], atol=1e-4)
    np.testing.assert_allclose(patch_rgb_from_corners(image, corners), rgb, rtol=1e-12)


def test_cli_calibrate_from_a_photograph_with_corner_points(tmp_path):
    from abs.cli.main import main
    from abs.io.images import write_exr

    xyz = reference_xyz()
    rgb = 0.5 * _camera_rgb(xyz)  # any exposure
    image = np.zeros((48, 64, 3), np.float32)
    for i in range(24):
        r, c = divmod(i, 6)
        image[8 + 9 * r - 3:8 + 9 * r + 4, 8 + 9 * c - 3:8 + 9 * c + 4] = rgb[i]
    write_exr(tmp_path / "chart.exr", image)
    out = tmp_path / "c.json"
    base = ["colour", "calibrate", "--image", str(tmp_path / "chart.exr"), "--degree", "1",
            "--no-refine", "--out", str(out)]
    assert main(base + ["--corners", "8,8,53,8,53,35,8,35"]) == 0
    assert json.loads(out.read_text())["delta_e00"]["after_mean"] < 1e-3
    # Corner points that put the last row below the image: patches 19-24 are missing.
    assert main(base + ["--corners", "8,8,53,8,53,50,8,50"]) == 2


def test_missing_patches_name_file_and_field():
    rgb = _camera_rgb(reference_xyz())
    rgb[[4, 20]] = np.nan
    with pytest.raises(InputError, match=r"chart\.json: rgb: missing patches \[5, 21\]"):
        check_patches(rgb, "chart.json", "rgb")
    with pytest.raises(InputError, match=r"chart\.json: rgb: expected 24 patches, got 23"):
        check_patches(rgb[:23], "chart.json", "rgb")


def test_cli_calibrate_apply_round_trip(tmp_path):
    from abs.cli.main import main
    from abs.io.images import read_image, write_exr

    xyz, white = reference_xyz(), reference_white_xyz()
    rgb = _camera_rgb(xyz)
    patches = tmp_path / "patches.json"
    patches.write_text(json.dumps({"rgb": rgb.tolist()}))
    out = tmp_path / "correction.json"
    assert main(["colour", "calibrate", "--patches", str(patches), "--degree", "1", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["space"] == "CIE RGB" and doc["delta_e00"]["after_mean"] < 1e-3
    image = np.repeat(rgb[None, :, :], 2, axis=0).astype(np.float32)  # 2 x 24 pixels
    write_exr(tmp_path / "cam.exr", image)
    assert main(["colour", "apply", str(out), str(tmp_path / "cam.exr"), "--out", str(tmp_path / "o")]) == 0
    got = read_image(tmp_path / "o" / "cam.exr")
    expect = colour.XYZ_to_RGB(xyz, "CIE RGB", illuminant=colour.XYZ_to_xy(white),
                               chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(got[0], expect, atol=1e-4)
    # A file with a missing patch fails with exit status 2 naming the file and field.
    patches.write_text(json.dumps({"rgb": rgb[:20].tolist()}))
    assert main(["colour", "calibrate", "--patches", str(patches), "--out", str(out)]) == 2


def test_correction_file_round_trip_and_errors(tmp_path):
    xyz, white = reference_xyz(), reference_white_xyz()
    c = calibrate(_camera_rgb(xyz) ** 1.1, xyz, white, degree=2, refine=False)
    path = tmp_path / "c.json"
    write_correction(path, c)
    back = read_correction(path)
    np.testing.assert_allclose(back.apply(np.ones((2, 2, 3))), c.apply(np.ones((2, 2, 3))))
    doc = json.loads(path.read_text())
    doc["rgb_to_xyz"] = doc["rgb_to_xyz"][:2]
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"c\.json: rgb_to_xyz: expected a finite 3x6 matrix"):
        read_correction(path)


def test_patches_from_a_label_mask():
    from abs.colour.chart import patch_rgb_from_labels

    rgb = _camera_rgb(reference_xyz())
    labels = np.zeros((8, 24), np.uint8)
    image = np.zeros((8, 24, 3))
    for i in range(24):
        r, c = divmod(i, 6)
        labels[2 * r:2 * r + 2, 4 * c:4 * c + 3] = i + 1
        image[2 * r:2 * r + 2, 4 * c:4 * c + 3] = rgb[i]
    np.testing.assert_allclose(patch_rgb_from_labels(image, labels), rgb)
    labels[labels == 7] = 0
    with pytest.raises(InputError, match=r"labels\.png: labels: missing patches \[7\]"):
        check_patches(patch_rgb_from_labels(image, labels), "labels.png", "labels")


def test_real_chart_measurements_calibrate_to_the_benchmark_numbers(tmp_path):
    """The shipped 24-patch UEA example (tests/data): training dE00 of the benchmark's table."""
    from pathlib import Path

    from abs.cli.main import main

    example = Path(__file__).parent / "data" / "uea_24_outdoor_cloudy.json"
    out = tmp_path / "c.json"
    assert main(["colour", "calibrate", "--patches", str(example), "--out", str(out)]) == 0
    de = json.loads(out.read_text())["delta_e00"]
    # benchmarks/results/colour_correction.json, uea-24-outdoor-cloudy, train: least squares
    # 1.72 +- 0.89, refined 1.27 +- 0.96.
    assert de["before_mean"] == pytest.approx(1.72, abs=0.01)
    assert de["after_mean"] == pytest.approx(1.27, abs=0.02)
