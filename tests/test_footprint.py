"""A built photograph's pixels as the sensor sites its build averaged (``processing`` in
``cameras.json``): the weights are the build's own, and a renderer that draws the sites and
applies them makes what the build makes of a sensor, where a Gaussian blur of the same variance
leaves structured errors (the demosaic's aliasing, the resampling's uneven blur)."""

from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

from abs.acquisition.blur import processing_blur
from abs.acquisition.camera_file import CameraModel
from abs.acquisition.demosaic import cfa_masks, demosaic
from abs.acquisition.footprint import processing_footprint
from abs.acquisition.undistort import pinhole_K, superpixel_camera, undistort_image
from abs.errors import CaptureError
from abs.io.capture import SensorProcessing, load_capture, save_capture
from abs.model.downsampling import downsample, downsample_camera
from abs.render import Camera
from abs.render.camera import SampleBoost
from abs.render.footprint import _tables
from conftest import sphere_in_view

DIST = np.array([-0.12, 0.02, 0.0005, -0.0005, 0.0])


def _camera(width, height, fov_deg=30.0):
    f = 0.5 * height / np.tan(np.radians(fov_deg) / 2)
    K = np.array([[f, 0, (width - 1) / 2 + 0.7], [0, f * 1.01, (height - 1) / 2 - 0.4], [0, 0, 1]])
    return CameraModel(width, height, K, DIST, np.eye(3), np.zeros(3))


@pytest.mark.parametrize("method", ["bilinear", "superpixel", None])
def test_footprint_reproduces_the_build(method):
    """Applied to any raw image, the weights give what the build's demosaicing and undistortion
    give, to the build's float32 rounding."""
    cam = _camera(64, 48)
    built = superpixel_camera(cam) if method == "superpixel" else cam
    K_new = pinhole_K(built)
    processing = SensorProcessing(64, 48, cam.K, cam.distortion, method, method and "GRBG")
    footprint = processing_footprint(processing, K_new, built.width, built.height)
    raw = np.random.default_rng(0).uniform(size=(48, 64))
    rgb = np.repeat(raw[..., None], 3, -1) if method is None else demosaic(raw, "GRBG", method, np.float64)
    expected = undistort_image(rgb, built, K_new)
    got = footprint.expected(np.repeat(raw.reshape(-1, 1), 3, 1))
    np.testing.assert_allclose(got, expected, atol=1e-6)  # the build computes in float32
    # A point of a site's square (as the renderer samples it) is found in that site (as edge
    # sampling splats it), through the calibrated distortion.
    offsets = np.random.default_rng(1).uniform(-0.49, 0.49, footprint.site_center.shape)
    points = footprint.site_center + np.einsum("kij,kj->ki", footprint.site_jacobian, offsets)
    np.testing.assert_array_equal(footprint.site_at(points), np.arange(len(points)))
    # The sites' squares land where the built pixels sample them: the weighted mean position of
    # a pixel's sites is the pixel (to the resampling's and demosaic's half-site offsets).
    P = footprint.weights[1]
    inner = np.zeros((built.height, built.width), bool)
    inner[4:-4, 4:-4] = True
    rows = np.flatnonzero(inner.ravel())
    mean_x = (P @ footprint.site_center[:, 0])[rows] / np.asarray(P.sum(1)).ravel()[rows]
    assert np.max(np.abs(mean_x - rows % built.width)) < 0.6


def _sensor_photograph(compiled, camera, cam: CameraModel, n: int, spp: int) -> np.ndarray:
    """The light on each site of the distorted sensor: a pinhole render at ``n`` times the
    resolution, resampled at the distorted positions of an n-times finer grid and area-averaged."""
    W, H = cam.width, cam.height
    xs = (np.arange(W * n) - (n - 1) / 2) / n
    ys = (np.arange(H * n) - (n - 1) / 2) / n
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(grid, cam.K, cam.distortion, criteria=crit).reshape(H * n, W * n, 2)
    f = n * cam.K[0, 0]
    w_r, h_r = (2 * int(np.ceil(f * np.abs(rays[..., k]).max())) + 6 for k in (0, 1))
    K_r = np.array([[f, 0, (w_r - 1) / 2], [0, f, (h_r - 1) / 2], [0, 0, 1]])
    pin = compiled.render(Camera(K_r, camera.R, camera.t, w_r, h_r), spp=spp, seed=11).numpy()
    mx = (f * rays[..., 0] + (w_r - 1) / 2).astype(np.float32)
    my = (f * rays[..., 1] + (h_r - 1) / 2).astype(np.float32)
    fine = cv2.remap(pin.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return cv2.resize(fine, (W, H), interpolation=cv2.INTER_AREA).astype(np.float64)


@pytest.mark.parametrize("method", ["bilinear", "superpixel"])
def test_rendered_sites_make_the_built_photograph(small_scene_dir, method):
    """A glass sphere before a checkerboard seen by a distorted Bayer sensor, built by bilinear
    or superpixel demosaicing and undistortion: the footprint's rendering matches the built
    photograph to its Monte-Carlo noise; the Gaussian ``blur_px`` model is off by several times
    more (superpixels: ``blur_px`` 0, a sharp rendering, which misses that red and blue are
    sampled a quarter superpixel off the centre)."""
    W, H = 48, 36
    compiled, pinhole = sphere_in_view(small_scene_dir, W, H)
    cam = _camera(W, H)
    built_camera = superpixel_camera(cam) if method == "superpixel" else cam
    w, h = built_camera.width, built_camera.height
    K_new = pinhole_K(built_camera)
    sensor = _sensor_photograph(compiled, pinhole, cam, 3, 1024)
    mosaic = np.sum(sensor * cfa_masks((H, W), "RGGB"), -1)
    built = undistort_image(demosaic(mosaic, "RGGB", method, np.float64), built_camera, K_new)
    footprint = processing_footprint(SensorProcessing(W, H, cam.K, cam.distortion, method, "RGGB"),
                                     K_new, w, h)
    inner = (slice(2, -2), slice(2, -2))

    def misfit(camera):
        renders = np.array([compiled.render(camera, spp=2048, seed=s).numpy() for s in (1, 2)])
        error = np.sqrt(np.mean((renders.mean(0) - built)[inner] ** 2))
        noise = np.sqrt(np.mean(((renders[0] - renders[1]) / 2)[inner] ** 2))
        return error, noise

    exact, noise = misfit(Camera(K_new, pinhole.R, pinhole.t, w, h, footprint=footprint))
    gaussian, _ = misfit(Camera(K_new, pinhole.R, pinhole.t, w, h, 1,
                                tuple(processing_blur(cam, K_new, method))))
    assert exact < 1.5 * noise + 0.002, (exact, noise)
    assert gaussian > 3 * exact, (gaussian, exact)


@pytest.fixture(scope="module")
def footprint_view(small_scene_dir):
    W, H = 24, 18
    compiled, pinhole = sphere_in_view(small_scene_dir, W, H)
    cam = _camera(W, H)
    K_new = pinhole_K(cam)
    fp = processing_footprint(SensorProcessing(W, H, cam.K, cam.distortion, "bilinear", "RGGB"),
                              K_new, W, H)
    return compiled, Camera(K_new, pinhole.R, pinhole.t, W, H, footprint=fp)


@pytest.mark.parametrize("boosted", [False, True])
def test_replay_equals_forward_mode_under_a_footprint(footprint_view, boosted):
    """Path replay's adjoint goes through the build's weights transposed: it agrees with forward
    mode sample for sample (also where a sample boost gives some sites more samples)."""
    compiled, camera = footprint_view
    if boosted:
        camera = replace(camera, boost=SampleBoost(6, 4, 16, 12, 3))
    weights = np.random.default_rng(0).uniform(-1, 1, (camera.height, camera.width, 3))
    image, gradient = compiled.render_backward(camera, weights, ["glass.absorption"], spp=8, seed=4,
                                               max_depth=6)
    for k in range(3):
        direction = np.eye(3)[k]
        primal, derivative = compiled.render_forward(camera, {"glass.absorption": direction}, spp=8,
                                                     seed=4, max_depth=6)
        forward = float(np.sum(derivative.numpy() * weights))
        assert gradient["glass.absorption"][k] == pytest.approx(forward, rel=2e-3,
                                                                abs=1e-6 * np.abs(weights).sum())
        np.testing.assert_allclose(primal.numpy(), image, rtol=1e-5, atol=1e-6)
    assert np.any(np.abs(gradient["glass.absorption"]) > 0)


@pytest.mark.parametrize("variant", ["plain", "downsampled", "boosted"])
def test_recording_is_the_render_under_a_footprint(footprint_view, variant):
    """A path-length recording splats each sample into every pixel that uses its site: reweighted
    at its own absorption it is the render with the same samples (also downsampled, where a
    site takes a quarter of the samples per pixel, and with a sample boost)."""
    compiled, camera = footprint_view
    if variant == "downsampled":
        camera = downsample_camera(camera, 2)
    elif variant == "boosted":
        camera = replace(camera, boost=SampleBoost(6, 4, 16, 12, 3))
    recording = compiled.record(camera, spp=16, seed=5,
                                absorption_per_m=compiled.get("glass.absorption"))
    direct = compiled.render(camera, spp=16, seed=5).numpy()
    np.testing.assert_allclose(compiled.render_recorded(recording, camera).numpy(), direct,
                               rtol=1e-4, atol=1e-5)


def test_downsampled_footprint_averages_the_full_resolution_weights():
    cam = _camera(32, 24)
    K_new = pinhole_K(cam)
    fp = processing_footprint(SensorProcessing(32, 24, cam.K, cam.distortion, "bilinear", "BGGR"),
                              K_new, 32, 24)
    values = np.random.default_rng(3).uniform(size=(32 * 24, 3))
    full = fp.expected(values)
    tables = _tables(fp, 2, 16, 12)
    local = values[tables.sites]
    for c in range(3):
        idx, w = tables.forward[c]
        coarse = np.sum(w * local[idx, c], axis=1).reshape(12, 16)
        np.testing.assert_allclose(coarse, downsample(full, 2)[..., c], atol=1e-12)
    camera = downsample_camera(Camera(K_new, np.eye(3), np.zeros(3), 32, 24, footprint=fp), 2)
    assert camera.footprint is fp and camera.block == 2


def test_capture_processing_round_trip_and_errors(tmp_path, monkeypatch):
    K = np.array([[50.0, 0, 15.5], [0, 50.0, 11.5], [0, 0, 1]])
    processing = SensorProcessing(32, 24, K, DIST, "bilinear", "RGGB", 0.3)
    image = np.ones((24, 32, 3), np.float32)
    capture = save_capture(tmp_path / "c", [{"name": "v0", "K": K, "R": np.eye(3), "t": [0, 0, 1]}],
                           {"v0": image}, processing={"v0": processing})
    view = capture.views[0]
    assert view.processing.key() == processing.key()
    camera = Camera.from_view(view)
    assert camera.footprint is not None and camera.blur_px == (0.0, 0.0, 0.0)
    assert load_capture(tmp_path / "c").views[0].processing.demosaic == "bilinear"
    assert load_capture(tmp_path / "c").views[0].processing.lens_blur_px == 0.3
    # A sensor too large for a footprint falls back to blur_px, saying so.
    monkeypatch.setattr("abs.render.camera.MAX_SENSOR_PIXELS", 32 * 24 - 1)
    with pytest.warns(UserWarning, match="too large.*blur_px"):
        assert Camera.from_view(view).footprint is None
    monkeypatch.undo()
    data = json.loads((tmp_path / "c" / "cameras.json").read_text())
    for change, field in ((lambda p: p.update(demosaic="ahd"), "processing.v0.demosaic"),
                          (lambda p: p.update(cfa_pattern="RGBG"), "processing.v0.cfa_pattern"),
                          (lambda p: p.update(distortion=[0.1, 0.2]), "processing.v0.distortion"),
                          (lambda p: p.update(width=0), "processing.v0.width"),
                          (lambda p: p.update(lens_blur_px=-0.5), "processing.v0.lens_blur_px"),
                          (lambda p: p.pop("K"), "processing.v0.K"),
                          (lambda p: p.update(colour=1), "processing.v0.colour")):
        broken = json.loads(json.dumps(data))
        change(broken["processing"]["v0"])
        (tmp_path / "c" / "cameras.json").write_text(json.dumps(broken))
        with pytest.raises(CaptureError, match=field.replace(".", r"\.")):
            load_capture(tmp_path / "c")
    broken = json.loads(json.dumps(data))
    broken["processing"]["v0"]["width"] = 64
    (tmp_path / "c" / "cameras.json").write_text(json.dumps(broken))
    with pytest.raises(CaptureError, match=r"processing\.v0: a 32x24 photograph cannot come"):
        load_capture(tmp_path / "c")
    broken = json.loads(json.dumps(data))
    broken["processing"]["v9"] = broken["processing"]["v0"]
    (tmp_path / "c" / "cameras.json").write_text(json.dumps(broken))
    with pytest.raises(CaptureError, match="no view has this name"):
        load_capture(tmp_path / "c")


def test_a_sample_boost_gives_its_sites_more_samples_and_changes_nothing_else(footprint_view):
    """Boosted sites average ``factor`` times the samples: the boosted pixels' noise falls, the
    image's expectation does not move."""
    compiled, camera = footprint_view
    boosted = replace(camera, boost=SampleBoost(6, 4, 16, 12, 4))
    assert boosted.samples(8) > camera.samples(8)
    plain = np.array([compiled.render(camera, spp=8, seed=s).numpy() for s in range(6)])
    more = np.array([compiled.render(boosted, spp=8, seed=s).numpy() for s in range(6)])
    inside = (slice(6, 10), slice(8, 14))  # pixels whose sites are all boosted
    assert np.std(more, 0)[inside].mean() < 0.75 * np.std(plain, 0)[inside].mean()
    reference = compiled.render(camera, spp=512, seed=99).numpy()
    for images in (plain, more):
        assert abs(float(np.mean(images.mean(0) - reference))) < 0.01


@pytest.mark.parametrize("lens_blur_px", [0.0, 0.6])
def test_pose_gradient_under_a_footprint(silhouette_scene_dir, lens_blur_px):
    """Edge sampling splats a moving silhouette's boundary term into the sensor site whose square
    holds each edge point (moved by a draw of the lens's point-spread function when there is
    one), then through the build's weights: forward mode with edges agrees with finite
    differences of footprint renders (an unlit sphere before a uniform environment: the boundary
    term is the whole gradient)."""
    from abs.camera.pinhole import intrinsics_from_fov, look_at
    from abs.render import compile_scene
    from abs.scene import load_scene
    from gradcheck import assert_gradients_agree, directional_gradient

    compiled = compile_scene(load_scene(silhouette_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.35]), np.array([0.0, 0.05, 0.0]))
    cam = CameraModel(24, 24, intrinsics_from_fov(24, 24, np.radians(25)), DIST, np.eye(3), np.zeros(3))
    K_new = pinhole_K(cam)
    fp = processing_footprint(SensorProcessing(24, 24, cam.K, DIST, "bilinear", "RGGB",
                                               lens_blur_px), K_new, 24, 24)
    camera = Camera(K_new, R, t, 24, 24, footprint=fp)
    import mitsuba as mi
    # Ramps, so the boundary terms of opposite edges add rather than cancel (steeper weights make
    # the finite differences' own step error show).
    v, u = np.mgrid[0:24, 0:24] / 23.0
    weights = mi.TensorXf(np.repeat((u + 2 * v)[..., None], 3, axis=2).astype(np.float32))
    for direction in ([1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]):
        res = directional_gradient(compiled, camera, "sphere.pose", direction, 0.003, weights,
                                   max_depth=1, spp=128, seeds=4)
        assert_gradients_agree(*res, rel=0.1)


def test_noise_of_a_built_photograph_is_estimated_at_its_level():
    """Demosaicing spreads a site's noise into its neighbours, which the white-noise estimator
    largely cancels; with the camera's footprint the estimate is the per-pixel level again."""
    from abs.model.noise import estimate_image_noise

    cam = _camera(96, 72)
    K_new = pinhole_K(cam)
    fp = processing_footprint(SensorProcessing(96, 72, cam.K, DIST, "bilinear", "RGGB"), K_new, 96, 72)
    camera = Camera(K_new, np.eye(3), np.zeros(3), 96, 72, footprint=fp)
    rng = np.random.default_rng(5)
    flat = np.full((72, 96), 0.5)
    built = [undistort_image(demosaic(flat + rng.normal(0, 0.01, flat.shape), "RGGB", "bilinear",
                                      np.float64), cam, K_new) for _ in range(2)]
    inner = (slice(4, -4), slice(4, -4))
    true = float(np.std((built[0] - built[1])[inner]) / np.sqrt(2))
    assert estimate_image_noise(built[0][inner]) < 0.75 * true  # the white-noise reading
    assert estimate_image_noise(built[0], camera) == pytest.approx(true, rel=0.12)


def test_noise_correlation_is_the_build_weights_outer_product():
    cam = _camera(20, 16)
    K_new = pinhole_K(cam)
    fp = processing_footprint(SensorProcessing(20, 16, cam.K, DIST, "bilinear", "RGGB"), K_new, 20, 16)
    film = Camera(K_new, np.eye(3), np.zeros(3), 20, 16, footprint=fp).film()
    X = np.random.default_rng(2).normal(size=(20 * 16, 3, 2))
    for c in range(3):
        P = fp.weights[c].toarray()
        expected = P @ P.T @ X[:, c] / film.white_noise_std() ** 2
        np.testing.assert_allclose(film.correlate(X)[:, c], expected, rtol=1e-4, atol=1e-5)
    diag = np.concatenate([np.sum(fp.weights[c].toarray() ** 2, 1) for c in range(3)])
    assert np.mean(diag) / film.white_noise_std() ** 2 == pytest.approx(1.0, rel=1e-6)


def test_a_lens_blur_spreads_each_sites_samples_by_its_point_spread_function():
    """Samples of a site fall in its square blurred by the lens's Gaussian: their covariance in
    the camera's pixels is ``J (I / 12 + sigma^2 I) J^T``."""
    import drjit as dr
    import mitsuba as mi

    cam = _camera(16, 12)
    K_new = pinhole_K(cam)
    sigma = 0.4
    fp = processing_footprint(SensorProcessing(16, 12, cam.K, DIST, "bilinear", "RGGB", sigma),
                              K_new, 16, 12)
    film = Camera(K_new, np.eye(3), np.zeros(3), 16, 12, footprint=fp).film()
    spp = 20000
    n = film.sites * film.site_spp(spp)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(3, n)
    site, x, y = film.positions(sampler, dr.arange(mi.UInt32, n), spp)
    site, x, y = site.numpy(), x.numpy(), y.numpy()
    local = film._local
    for k in (40, 77):
        chosen = site == local[k]
        J = fp.site_jacobian[k]
        expected = J @ (np.eye(2) * (1 / 12 + sigma ** 2)) @ J.T
        np.testing.assert_allclose(np.cov(np.stack([x[chosen], y[chosen]])), expected, rtol=0.05,
                                   atol=2e-3)
        np.testing.assert_allclose([x[chosen].mean(), y[chosen].mean()], fp.site_center[k], atol=0.01)
