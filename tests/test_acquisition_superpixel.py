"""Superpixel demosaicing (``demosaic = "superpixel"``): the 2x2-cell RGB, the half-resolution
camera, and ``abs capture build`` with it."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from abs.acquisition.build import build_capture
from abs.acquisition.camera_file import CameraModel, write_camera_file
from abs.acquisition.demosaic import (CFA_PATTERNS, cfa_masks, demosaic_superpixel,
                                      superpixel_any, superpixel_K, superpixel_mask)
from abs.acquisition.undistort import pinhole_K, superpixel_camera, undistort_mask
from abs.cli.main import main
from abs.errors import InputError
from abs.io.capture import load_capture
from abs.io.images import write_exr

K = np.array([[60.0, 0, 31.2], [0, 61.0, 23.8], [0, 0, 1]])
DIST = np.array([-0.15, 0.03, 0.001, -0.002, 0.0])


@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_superpixel_is_exact(pattern):
    rng = np.random.default_rng(1)
    mosaic = rng.integers(0, 4096, (6, 8)).astype(np.float64)
    got = demosaic_superpixel(mosaic, pattern)
    assert got.shape == (3, 4, 3) and got.dtype == np.float32
    for j in range(3):
        for i in range(4):
            cell = mosaic[2 * j:2 * j + 2, 2 * i:2 * i + 2].ravel()  # row-major, as the pattern
            for c, colour in enumerate("RGB"):
                expected = np.mean([cell[k] for k in range(4) if pattern[k] == colour])
                assert got[j, i, c] == np.float32(expected)
    # A mosaic of an image constant over each cell gives that image back.
    cells = rng.uniform(0, 1000, (3, 4, 3))
    full = np.repeat(np.repeat(cells, 2, 0), 2, 1)
    mosaic = np.sum(full * cfa_masks((6, 8), pattern), -1)
    np.testing.assert_allclose(demosaic_superpixel(mosaic, pattern), cells, rtol=1e-6)
    # Saturation: a colour of a superpixel is flagged when any of its sites of that colour is.
    flags = np.zeros((6, 8), bool)
    flags[2 + pattern.index("G") // 2, 4 + pattern.index("G") % 2] = True  # one green site
    sat = superpixel_any(flags, pattern)
    assert sat[1, 2].tolist() == [False, True, False] and sat.sum() == 1


def test_superpixel_rejects_odd_sizes_and_keeps_full_cells_of_masks():
    with pytest.raises(InputError, match="7x6 pixels; superpixel demosaicing needs an even"):
        demosaic_superpixel(np.zeros((6, 7)), "RGGB")
    mask = np.zeros((4, 6), bool)
    mask[0:2, 0:3] = True  # cell (0, 0) whole, cell (0, 1) half
    np.testing.assert_array_equal(superpixel_mask(mask), [[True, False, False],
                                                          [False, False, False]])


def test_half_resolution_camera_projects_onto_superpixel_centres():
    """A point that projects to full-resolution (u, v) projects to ((u - 0.5) / 2, (v - 0.5) / 2)
    in the superpixel image, with and without distortion: the centre of 2x2 cell (i, j),
    full-resolution (2i + 0.5, 2j + 0.5), is superpixel (i, j)."""
    full = CameraModel(64, 48, K, DIST, R=np.eye(3), t=np.array([0.0, 0.0, 2.0]), rms_px=0.2)
    half = superpixel_camera(full)
    assert (half.width, half.height) == (32, 24) and half.rms_px == pytest.approx(0.1)
    np.testing.assert_allclose(half.K, [[30.0, 0, 15.35], [0, 30.5, 11.65], [0, 0, 1]])
    np.testing.assert_array_equal(half.distortion, DIST)
    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-0.8, 0.8, 50), rng.uniform(-0.6, 0.6, 50),
                         rng.uniform(-0.5, 0.5, 50)])
    rvec = np.zeros(3)
    for dist in (DIST, np.zeros(5)):
        uv, _ = cv2.projectPoints(X, rvec, full.t, full.K, dist)
        uv_half, _ = cv2.projectPoints(X, rvec, half.t, half.K, dist)
        np.testing.assert_allclose(uv_half.reshape(-1, 2), (uv.reshape(-1, 2) - 0.5) / 2,
                                   atol=1e-9)
    # Cell centres land on integer superpixels.
    cell_centres = np.array([[2 * 5 + 0.5, 2 * 7 + 0.5, 1.0], [2 * 0 + 0.5, 2 * 0 + 0.5, 1.0]])
    np.testing.assert_allclose((superpixel_K(K) @ np.linalg.inv(K) @ cell_centres.T).T[:, :2],
                               [[5, 7], [0, 0]], atol=1e-12)
    with pytest.raises(InputError, match="even width and height"):
        superpixel_camera(CameraModel(63, 48, K, DIST))


def _blobs_setup(tmp_path: Path, width=64, height=48) -> tuple[Path, np.ndarray, CameraModel]:
    """A distorted camera seeing Gaussian blobs at known 3-D points, as 16-bit RGGB mosaics of a
    two-frame bracket with a dark frame."""
    cam = CameraModel(width, height, K, DIST, R=np.eye(3), t=np.array([0.0, 0.0, 2.0]))
    write_camera_file(tmp_path / "cams.json", {"cam": cam})
    X = np.array([[-0.55, -0.40, 0.0], [0.50, -0.35, 0.1], [-0.45, 0.35, -0.1],
                  [0.55, 0.40, 0.0], [0.0, 0.0, 0.0], [0.0, -0.45, 0.2]])
    uv, _ = cv2.projectPoints(X, np.zeros(3), cam.t, K, DIST)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    radiance = np.full((height, width, 3), 1.0e3)
    for x, y in uv.reshape(-1, 2):
        radiance += 4.0e5 * np.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * 2.0 ** 2))[..., None]
    masks = cfa_masks((height, width), "RGGB")
    t = [0.01, 0.04]
    names = []
    for ti in t:
        names.append(f"f{int(ti * 1000):03d}ms.tif")
        mosaic = np.sum(radiance * ti * masks, -1) + 100.0
        cv2.imwrite(str(tmp_path / names[-1]), np.round(np.clip(mosaic, 0, 65535)).astype(np.uint16))
    cv2.imwrite(str(tmp_path / "dark.tif"), np.full((height, width), 100, np.uint16))
    spec = {"cameras": "cams.json", "cfa_pattern": "RGGB", "demosaic": "superpixel",
            "views": [{"name": "v0", "camera": "cam", "frames": names, "exposures_s": t,
                       "darks": ["dark.tif"] * 2}]}
    (tmp_path / "build.json").write_text(json.dumps(spec))
    return tmp_path / "build.json", X, cam


def test_superpixel_build_half_size_camera_and_positions(tmp_path: Path):
    build_file, X, cam = _blobs_setup(tmp_path)
    capture, merges = build_capture(build_file, tmp_path / "capture")
    view = load_capture(tmp_path / "capture").view("v0")
    img = view.read_image()
    assert img.shape == (24, 32, 3) and merges["v0"].radiance.shape == (24, 32, 3)
    half = superpixel_camera(cam)
    np.testing.assert_allclose(view.K, pinhole_K(half))
    np.testing.assert_allclose(view.t, cam.t)
    # Linear values: the background, away from blobs and borders, is 1e3 DN/s in every colour.
    assert np.median(img[..., 1]) == pytest.approx(1.0e3, rel=0.02)
    # Its noise: a superpixel's green averages two sites, so half the variance of red or blue.
    sd = view.read_noise()
    ratio = np.median(sd[..., 1] ** 2) / np.median(sd[..., 0] ** 2)
    assert ratio == pytest.approx(0.5, rel=0.05)
    # Each blob's centroid in the written (undistorted, half-size) image is where cameras.json's
    # pinhole projects its 3-D point (green: the mean of the two green sites is cell-centred).
    proj, _ = cv2.projectPoints(X, np.zeros(3), np.asarray(view.t, float),
                                np.asarray(view.K, float), np.zeros(5))
    green = img[..., 1].astype(np.float64) - 1.0e3
    v, u = np.mgrid[0:24, 0:32]
    for x, y in proj.reshape(-1, 2):
        win = (np.abs(u - x) <= 3) & (np.abs(v - y) <= 3)
        w = green * win
        centroid = np.array([np.sum(w * u), np.sum(w * v)]) / w.sum()
        np.testing.assert_allclose(centroid, [x, y], atol=0.06)  # a 1/4 px convention slip: 0.25
    # The full-resolution build's projection, mapped to superpixels, agrees too (sub-pixel).
    full_capture, _ = build_capture(build_file, tmp_path / "full", demosaic="bilinear")
    full_view = full_capture.view("v0")
    assert full_view.read_image().shape == (48, 64, 3)
    proj_full, _ = cv2.projectPoints(X, np.zeros(3), np.asarray(full_view.t, float),
                                     np.asarray(full_view.K, float), np.zeros(5))
    np.testing.assert_allclose(proj.reshape(-1, 2), (proj_full.reshape(-1, 2) - 0.5) / 2,
                               atol=0.1)


def test_superpixel_masks_cli_and_bad_inputs(tmp_path: Path):
    build_file, _, cam = _blobs_setup(tmp_path)
    spec = json.loads(build_file.read_text())
    mask = np.zeros((48, 64), np.uint8)
    mask[10:31, 20:45] = 255  # odd edges: half-covered cells are left out
    cv2.imwrite(str(tmp_path / "v0_mask.png"), mask)
    spec["views"][0]["mask"] = "v0_mask.png"
    spec.pop("demosaic")
    build_file.write_text(json.dumps(spec))
    # The command-line flag overrides the build file (here: its default, bilinear).
    assert main(["capture", "build", str(build_file), "--out", str(tmp_path / "cap"),
                 "--demosaic", "superpixel"]) == 0
    view = load_capture(tmp_path / "cap").view("v0")
    assert view.read_image().shape == (24, 32, 3)
    half = superpixel_camera(cam)
    expected = undistort_mask(superpixel_mask(mask > 0), half, pinhole_K(half))
    np.testing.assert_array_equal(view.read_mask(), expected)
    assert expected.sum() > 0
    # Unknown method.
    spec["demosaic"] = "malvar"
    build_file.write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"build.json: demosaic: expected one of bilinear, "
                                         r"superpixel, got 'malvar'"):
        build_capture(build_file, tmp_path / "c1")
    # Odd image sizes: the error names the build file, the field and the frame.
    spec["demosaic"] = "superpixel"
    spec["views"][0].pop("mask")
    for name in spec["views"][0]["frames"]:
        cv2.imwrite(str(tmp_path / name), np.full((48, 63), 200, np.uint16))
    build_file.write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"build.json: views\[0\]\.frames\[0\]: f010ms.tif is "
                                         r"63x48 pixels: demosaic \"superpixel\" needs an even "
                                         r"width and height"):
        build_capture(build_file, tmp_path / "c2")
    assert main(["capture", "build", str(build_file), "--out", str(tmp_path / "c3")]) == 2
    # Odd darks too.
    _blobs_setup(tmp_path)
    cv2.imwrite(str(tmp_path / "dark.tif"), np.full((47, 64), 100, np.uint16))
    with pytest.raises(InputError, match=r"views\[0\]\.darks\[0\]: dark.tif is 64x47 pixels"):
        build_capture(build_file, tmp_path / "c4")
    # EXR frames are not mosaics.
    write_exr(tmp_path / "lin.exr", np.ones((48, 64, 3), np.float32))
    spec = {"cameras": "cams.json", "demosaic": "superpixel",
            "views": [{"name": "v0", "camera": "cam", "frames": ["lin.exr"]}]}
    build_file.write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"views\[0\]\.frames\[0\]: lin.exr is a linear RGB EXR"):
        build_capture(build_file, tmp_path / "c5")
