"""``abs capture build`` and ``abs calibrate`` end to end on small synthetic files."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from abs.acquisition.build import build_capture
from abs.acquisition.camera_file import CameraModel, write_camera_file
from abs.acquisition.demosaic import cfa_masks
from abs.acquisition.undistort import pinhole_K
from abs.cli.main import main
from abs.errors import InputError
from abs.io.capture import load_capture

K = np.array([[60.0, 0, 31.2], [0, 60.0, 23.8], [0, 0, 1]])
DIST = np.array([-0.15, 0.03, 0.0, 0.0, 0.0])


def _write_bracket(folder: Path, radiance: np.ndarray, t: np.ndarray, pattern="RGGB") -> list[str]:
    """16-bit RGGB mosaics of a linear RGB radiance (DN/s) with 100 DN black level."""
    masks = cfa_masks(radiance.shape[:2], pattern)
    names = []
    for ti in t:
        mosaic = np.sum(radiance * ti * masks, axis=-1) + 100.0
        name = f"frame_{int(round(ti * 1000)):04d}ms.tif"
        cv2.imwrite(str(folder / name), np.clip(np.round(mosaic), 0, 65535).astype(np.uint16))
        names.append(name)
    cv2.imwrite(str(folder / "dark.tif"), np.full(radiance.shape[:2], 100, np.uint16))
    return names


def _setup(tmp_path: Path) -> tuple[Path, np.ndarray]:
    write_camera_file(tmp_path / "cams.json", {
        "cam": CameraModel(64, 48, K, DIST, R=np.eye(3), t=np.array([0.0, 0.0, 2.0]))})
    v, u = np.mgrid[0:48, 0:64]
    radiance = np.stack([2e4 + 0 * u, 5e3 + 100.0 * u, 1.5e6 * np.exp(-v / 8.0)], -1)
    t = np.array([0.001, 0.004, 0.016, 0.064])
    frames = _write_bracket(tmp_path, radiance, t)
    spec = {"cameras": "cams.json", "cfa_pattern": "RGGB",
            "views": [{"name": "v0", "camera": "cam", "frames": frames,
                       "exposures_s": t.tolist(), "darks": ["dark.tif"] * 4},
                      {"name": "v1", "camera": "cam", "frames": frames[1:],
                       "exposures_s": t[1:].tolist(), "darks": ["dark.tif"] * 3,
                       "holdout": True}]}
    (tmp_path / "build.json").write_text(json.dumps(spec))
    return tmp_path / "build.json", radiance


def test_build_writes_a_loadable_capture(tmp_path: Path):
    build_file, radiance = _setup(tmp_path)
    capture, merges = build_capture(build_file, tmp_path / "capture")
    again = load_capture(tmp_path / "capture")
    assert again.names == ("v0", "v1") and again.holdout_views[0].name == "v1"
    view = again.view("v0")
    K_new = pinhole_K(CameraModel(64, 48, K, DIST))
    np.testing.assert_allclose(view.K, K_new)
    np.testing.assert_allclose(view.t, [0, 0, 2.0])
    # The merged (pre-undistortion) values are the linear radiance in DN/s where not saturated.
    merged = merges["v0"].radiance
    inner = (slice(2, -2), slice(2, -2))
    # (16-bit rounding of each frame: at most 2 DN over >= 1700 DN summed.)
    np.testing.assert_allclose(merged[inner][..., :2], radiance[inner][..., :2], rtol=2e-3)
    # Blue spans 1.5e6 .. 4e3 DN/s: its top rows saturate the 64 ms frame, which is left out.
    blue = merges["v0"]
    assert blue.used[0, 0, 10, 2] and not blue.used[-1, 0, 10, 2]
    # The image written is the undistorted merge: constant red stays constant inside.
    red = view.read_image()[10:-10, 10:-10, 0]
    np.testing.assert_allclose(red, 2e4, rtol=2e-3)
    # With it, its noise: shot noise of the 1700 DN that the four frames' red sums, read noise of
    # 1 DN in each, over the 85 ms they sum: sqrt(1704) / 0.085 DN/s.
    sd = view.read_noise()
    np.testing.assert_allclose(sd[10:-10, 10:-10, 0], np.sqrt(1704.0) / 0.085, rtol=5e-3)
    # Blue's bright rows use the short frames only: noisier in DN/s, less noisy relative to it.
    blue, blue_sd = view.read_image()[..., 2], sd[..., 2]
    assert blue_sd[8, 32] > blue_sd[40, 32] and blue_sd[8, 32] / blue[8, 32] < blue_sd[40, 32] / blue[40, 32]
    # How each photograph was made, for fits to render exactly (abs.acquisition.footprint).
    processing = view.processing
    assert (processing.width, processing.height, processing.demosaic, processing.cfa_pattern,
            processing.lens_blur_px) == (64, 48, "bilinear", "RGGB", 0.0)
    np.testing.assert_allclose(processing.K, K)
    np.testing.assert_allclose(processing.distortion, DIST)


def test_build_records_a_given_lens_blur(tmp_path: Path):
    build_file, _ = _setup(tmp_path)
    spec = json.loads(build_file.read_text())
    build_file.write_text(json.dumps({**spec, "lens_blur_px": 0.4}))
    capture, _ = build_capture(build_file, tmp_path / "capture")
    assert {v.processing.lens_blur_px for v in capture.views} == {0.4}
    build_file.write_text(json.dumps({**spec, "lens_blur_px": "0.4"}))
    with pytest.raises(InputError, match=r"build.json: lens_blur_px"):
        build_capture(build_file, tmp_path / "capture2")


def test_build_errors_name_file_and_field(tmp_path: Path):
    build_file, _ = _setup(tmp_path)
    spec = json.loads(build_file.read_text())
    spec["views"][0]["exposures_s"] = [0.004, 0.001, 0.016, 0.064]
    build_file.write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"build.json: views\[0\].*exposures.*increase strictly"):
        build_capture(build_file, tmp_path / "capture")
    spec["views"][0]["exposures_s"] = [0.001, 0.004, 0.016, 0.064]
    cv2.imwrite(str(tmp_path / "small.tif"), np.zeros((40, 64), np.uint16))
    spec["views"][0]["frames"][2] = "small.tif"
    build_file.write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"views\[0\].frames: mixed image sizes"):
        build_capture(build_file, tmp_path / "capture")
    spec["views"][0]["frames"][2] = "photo.xyz"
    build_file.write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"photo.xyz: unreadable raw format"):
        build_capture(build_file, tmp_path / "capture")


def test_cli_build_and_calibrate_errors(tmp_path: Path, capsys):
    build_file, _ = _setup(tmp_path)
    assert main(["capture", "build", str(build_file), "--out", str(tmp_path / "cap"),
                 "--report", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "cap" / "cameras.json").is_file()
    assert (tmp_path / "rep" / "v0_weight.png").is_file() and (tmp_path / "rep" / "v0_noise.png").is_file()
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((48, 64), 128, np.uint8))
    assert main(["calibrate", "intrinsics", str(blank), "--board", "checkerboard:9x6:25mm",
                 "--out", str(tmp_path / "c.json")]) == 2
    assert "not found in any of the 1 images" in capsys.readouterr().err


def test_white_level_of_a_12_bit_sensor_in_16_bit_files(tmp_path: Path):
    """12-bit data in 16-bit TIFFs saturate at 4095, which only ``white_level`` can say: without
    it the clipped long frame is taken as valid and the merge is biased low."""
    write_camera_file(tmp_path / "cams.json", {"cam": CameraModel(64, 48, K, np.zeros(5))})
    radiance = np.full((48, 64, 3), 1.0e5)  # DN/s: 100 DN at 1 ms, clipped at 100 ms
    t = np.array([0.001, 0.01, 0.1])
    masks = cfa_masks((48, 64), "RGGB")
    names = []
    for ti in t:
        mosaic = np.minimum(np.sum(radiance * ti * masks, axis=-1) + 100.0, 4095.0)
        names.append(f"f{int(ti * 1000)}.tif")
        cv2.imwrite(str(tmp_path / names[-1]), np.round(mosaic).astype(np.uint16))
    cv2.imwrite(str(tmp_path / "dark.tif"), np.full((48, 64), 100, np.uint16))
    spec = {"cameras": "cams.json", "cfa_pattern": "RGGB",
            "views": [{"name": "v0", "camera": "cam", "frames": names, "exposures_s": t.tolist(),
                       "darks": ["dark.tif"] * 3}]}
    (tmp_path / "build.json").write_text(json.dumps(spec))
    _, merges = build_capture(tmp_path / "build.json", tmp_path / "a")
    inner = (slice(2, -2), slice(2, -2))
    assert merges["v0"].radiance[inner].mean() < 0.5e5
    spec["white_level"] = 4095
    (tmp_path / "build.json").write_text(json.dumps(spec))
    _, merges = build_capture(tmp_path / "build.json", tmp_path / "b")
    np.testing.assert_allclose(merges["v0"].radiance[inner], 1.0e5, rtol=1e-3)
    spec["white_level"] = "4095"
    (tmp_path / "build.json").write_text(json.dumps(spec))
    with pytest.raises(InputError, match=r"build.json: white_level: expected a positive number"):
        build_capture(tmp_path / "build.json", tmp_path / "c")


def test_build_undistorts_and_writes_masks(tmp_path: Path):
    build_file, _ = _setup(tmp_path)
    spec = json.loads(build_file.read_text())
    mask = np.zeros((48, 64), np.uint8)
    mask[10:30, 20:44] = 255  # drawn on the original (distorted) frames
    cv2.imwrite(str(tmp_path / "v0_mask.png"), mask)
    spec["views"][0]["mask"] = "v0_mask.png"
    build_file.write_text(json.dumps(spec))
    build_capture(build_file, tmp_path / "capture")
    view = load_capture(tmp_path / "capture").view("v0")
    got = view.read_mask()
    cam = CameraModel(64, 48, K, DIST)
    from abs.acquisition.undistort import undistort_mask
    np.testing.assert_array_equal(got, undistort_mask(mask > 0, cam, pinhole_K(cam)))
    # Barrel distortion removed: the rectangle's undistorted area differs but its centre stays put.
    assert abs(got.sum() / (mask > 0).sum() - 1) < 0.2
    assert load_capture(tmp_path / "capture").view("v1").mask is None
    cv2.imwrite(str(tmp_path / "v0_mask.png"), np.zeros((40, 64), np.uint8))
    with pytest.raises(InputError, match="v0_mask.png"):
        build_capture(build_file, tmp_path / "capture2")
