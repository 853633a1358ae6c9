"""The blur of a capture build's processing: measured from the build's own demosaicing and
undistortion, written to ``cameras.json`` (``blur_px``) and applied to renderings by the sensor."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import mitsuba as mi
import numpy as np
import pytest

from abs.acquisition.blur import PIXEL_FOOTPRINT_VARIANCE_PX2, processing_blur
from abs.acquisition.build import build_capture
from abs.acquisition.camera_file import CameraModel
from abs.acquisition.demosaic import cfa_masks, demosaic_bilinear
from abs.acquisition.undistort import (pinhole_K, remap_bilinear, superpixel_camera,
                                       undistortion_maps)
from abs.errors import CaptureError
from abs.io.capture import load_capture, save_capture
from abs.model.downsampling import downsample_camera
from abs.render import Camera
from abs.render.sensor import Sensor, blur_kernel

K = np.array([[120.0, 0, 63.5], [0, 120.0, 47.5], [0, 0, 1]])
DIST = np.array([-0.12, 0.02, 0.0005, -0.0005, 0.0])


def test_blur_kernel_has_the_asked_variance():
    assert np.array_equal(blur_kernel(0.0), [1.0])
    for sigma in (0.05, 0.3, 0.7071, 1.4):
        k = blur_kernel(sigma)
        offsets = np.arange(len(k)) - len(k) // 2
        assert np.all(k >= 0) and np.isclose(k.sum(), 1.0) and np.allclose(k, k[::-1])
        assert np.isclose(np.sum(k * offsets ** 2), sigma ** 2, rtol=1e-9)
    with pytest.raises(ValueError, match="blur"):
        blur_kernel(-0.1)


def test_renderer_footprint_matches_the_stated_variance():
    """The renderer draws each pixel with a tent of radius 1 (mi.warp.interval_to_tent): its
    variance is the footprint processing_blur subtracts."""
    u = (np.arange(200000) + 0.5) / 200000
    offsets = mi.warp.interval_to_tent(mi.Float(u)).numpy()
    assert np.isclose(np.mean(offsets ** 2), PIXEL_FOOTPRINT_VARIANCE_PX2, rtol=1e-3)


def test_processing_blur_without_distortion_is_the_demosaic_kernels():
    """Bilinear demosaicing averages over its kernels' phases to [1 2 1]/4 per axis for red and
    blue (variance 1/2 pixel^2) and [1 4 1]/6-like green (1/4); a pinhole camera needs no
    resampling. Superpixels sample sites smaller than their pixel: no blur beyond the footprint."""
    cam = CameraModel(64, 48, K / 2 + np.diag([0, 0, 0.5]), np.zeros(5), np.eye(3), np.zeros(3))
    np.testing.assert_allclose(processing_blur(cam, cam.K), np.sqrt([0.5, 0.25, 0.5]), atol=1e-9)
    np.testing.assert_allclose(processing_blur(cam, cam.K, None), 0.0, atol=1e-9)
    half = pinhole_K(superpixel_camera(cam))
    np.testing.assert_allclose(processing_blur(cam, half, "superpixel"), 0.0)


def test_tiles_measure_what_the_whole_frame_does():
    """A large sensor is measured on 3 x 3 tiles (memory): the same blur as the whole frame."""
    K_big = np.array([[700.0, 0, 599.5], [0, 700.0, 449.5], [0, 0, 1]])
    for method, size in (("bilinear", (1200, 900)), ("superpixel", (1200, 900)), (None, (1200, 900))):
        cam = CameraModel(*size, K_big, DIST, np.eye(3), np.zeros(3))
        built = superpixel_camera(cam) if method == "superpixel" else cam
        K_new = pinhole_K(built)
        whole = processing_blur(cam, K_new, method)
        tiled = processing_blur(cam, K_new, method, whole_frame_px=100_000)
        np.testing.assert_allclose(tiled, whole, atol=0.005, err_msg=str(method))


def test_processing_blur_explains_what_the_pipeline_does_to_fine_detail():
    """A smooth pattern of 5-10 pixel periods, mosaiced, demosaiced and undistorted by the build's
    own functions, against the same pattern sampled exactly at the undistorted pixels: blurred by
    processing_blur's Gaussian, the exact image is closer to the built one by a large factor, and
    no other Gaussian width does clearly better (what is left is the demosaic's aliasing, which
    depends on each pixel's CFA phase and no blur can make)."""
    cam = CameraModel(128, 96, K, DIST, np.eye(3), np.zeros(3))
    K_new = pinhole_K(cam)
    rng = np.random.default_rng(0)
    waves = [(rng.uniform(0, 2 * np.pi), 2 * np.pi / rng.uniform(5, 10), rng.uniform(0, np.pi))
             for _ in range(6)]

    def pattern(x, y):
        return 1.0 + sum(0.1 * np.sin(k * (np.cos(a) * x + np.sin(a) * y) + p) for p, k, a in waves)

    v, u = np.mgrid[0:96, 0:128].astype(np.float64)
    plane = pattern(u, v)
    mosaic = np.sum(np.repeat(plane[..., None], 3, -1) * cfa_masks(plane.shape, "RGGB"), -1)
    map_x, map_y = undistortion_maps(cam, K_new)
    built = remap_bilinear(demosaic_bilinear(mosaic, "RGGB", np.float64), map_x, map_y, np.float64)
    exact = pattern(map_x.astype(np.float64), map_y.astype(np.float64))
    sigma = processing_blur(cam, K_new)
    inner = (slice(8, -8), slice(8, -8))

    def error(c, s):
        k = blur_kernel(s)
        blurred = cv2.sepFilter2D(exact, -1, k, k, borderType=cv2.BORDER_REPLICATE)
        return np.sqrt(np.mean((built[..., c] - blurred)[inner] ** 2))

    for c in range(3):
        model_error = error(c, sigma[c])
        best = min(error(c, s) for s in np.arange(0.1, 1.5, 0.05))
        assert model_error < 0.45 * error(c, 0.0), (c, model_error, error(c, 0.0))
        assert model_error < 1.1 * best, (c, model_error, best)


def test_sensor_blur_is_a_separable_convolution_with_repeated_edges():
    rng = np.random.default_rng(2)
    image = rng.uniform(0, 1, (20, 30, 3)).astype(np.float32)
    blur = (0.8, 0.5, 1.3)
    camera = Camera(K, np.eye(3), np.zeros(3), 30, 20, blur_px=blur)
    sensor = Sensor([0.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    out = sensor.apply(mi.TensorXf(image), camera).numpy()
    for c in range(3):
        k = blur_kernel(blur[c])
        expected = cv2.sepFilter2D(image[..., c].astype(np.float64), -1, k, k,
                                   borderType=cv2.BORDER_REPLICATE)
        np.testing.assert_allclose(out[..., c], expected, rtol=1e-5, atol=1e-6)
    # No blur: the image bit for bit (the sensor skips the convolution).
    plain = sensor.apply(mi.TensorXf(image), Camera(K, np.eye(3), np.zeros(3), 30, 20)).numpy()
    assert np.array_equal(plain, image)
    # A downsampled camera blurs its block pixels by blur / block, and keeps the blur.
    coarse = downsample_camera(Camera(K, np.eye(3), np.zeros(3), 60, 40, blur_px=blur), 2)
    assert coarse.blur_px == blur
    out2 = sensor.apply(mi.TensorXf(image), coarse).numpy()
    k = blur_kernel(blur[0] / 2)
    np.testing.assert_allclose(out2[..., 0], cv2.sepFilter2D(image[..., 0].astype(np.float64), -1,
                                                             k, k, borderType=cv2.BORDER_REPLICATE),
                               rtol=1e-5, atol=1e-6)


def _view():
    return {"name": "a", "K": K, "R": np.eye(3), "t": [0.0, 0.0, 1.0]}


def test_capture_blur_round_trip_and_errors(tmp_path: Path):
    image = {"a": np.ones((96, 128, 3))}
    plain = save_capture(tmp_path / "plain", [_view()], image)
    assert plain.views[0].blur_px == (0.0, 0.0, 0.0)
    assert "blur_px" not in json.loads((tmp_path / "plain/cameras.json").read_text())
    blurred = save_capture(tmp_path / "blurred", [_view()], image, blur_px=[0.7, 0.5, 0.7])
    assert blurred.views[0].blur_px == (0.7, 0.5, 0.7)
    assert Camera.from_view(blurred.views[0]).blur_px == (0.7, 0.5, 0.7)
    # Views carry it into a copy; views that disagree must be told which to keep.
    assert save_capture(tmp_path / "copy", blurred.views).views[0].blur_px == (0.7, 0.5, 0.7)
    other = save_capture(tmp_path / "other", [{**_view(), "name": "b"}], {"b": image["a"]})
    with pytest.raises(CaptureError, match="blur_px.*differ"):
        save_capture(tmp_path / "mixed", [blurred.views[0], other.views[0]])
    for bad in ([0.7, 0.5], [0.7, -0.1, 0.7], "wide", [0.7, float("nan"), 0.7]):
        data = json.loads((tmp_path / "blurred/cameras.json").read_text())
        data["blur_px"] = bad
        (tmp_path / "blurred/cameras.json").write_text(json.dumps(data))
        with pytest.raises(CaptureError, match=r"cameras\.json: blur_px"):
            load_capture(tmp_path / "blurred")


def test_build_writes_its_processing_blur(tmp_path: Path):
    from test_acquisition_build import _setup

    build_file, _ = _setup(tmp_path)
    capture, _ = build_capture(build_file, tmp_path / "capture")
    data = json.loads((tmp_path / "capture/cameras.json").read_text())
    from test_acquisition_build import DIST as dist, K as k

    cam = CameraModel(64, 48, k, dist, np.eye(3), np.zeros(3))
    expected = processing_blur(cam, pinhole_K(cam), "bilinear", "RGGB")
    np.testing.assert_allclose(data["blur_px"], expected)
    assert capture.views[0].blur_px == tuple(expected)
    assert 0.5 < expected[0] < 1.0 and expected[1] < expected[0]
