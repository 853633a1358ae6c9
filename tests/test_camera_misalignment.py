"""``[sensor] intrinsics_offset`` and ``camera_turn`` (the ``camera_misalignment`` effect's two
forms): exact at zero, the camera they name (against the mappings ``K K'^-1`` and
``K R^T K'^-1`` computed here in numpy, and against the path tracer rendering through the offset
or turned camera), derivatives equal to finite differences, read and written through the scene
file."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.diagnosis.effects import effects
from abs.model.downsampling import downsample_camera
from abs.render import Camera, compile_scene
from abs.render.sensor import Sensor
from abs.scene import load_scene, write_scene
from gradcheck import assert_gradients_agree, directional_gradient

W, H = 24, 18
SPP = 8
NULL = dict(vignetting=[0.0, 0.0], response=[1.0, 1.0, 1.0], stray_light=[0.0, 0.0, 0.0])


def _camera(width=W, height=H, skew=0.0) -> Camera:
    K = intrinsics_from_fov(width, height, np.radians(40))
    K[0, 1] = skew
    K[0, 2] += 1.3  # off-centre principal point: the scaling must centre on it
    K[1, 2] -= 0.6
    R, t = look_at(np.array([0.0, 0.08, 0.32]), np.array([0.0, 0.05, 0.0]))
    return Camera(K, R, t, width, height)


def test_zero_offset_is_bitwise_the_identity():
    """Every pixel back bit for bit, zeros and values over many octaves included, on an ordinary
    and a downsampled camera."""
    image = np.random.default_rng(1).lognormal(-2.0, 3.0, (H, W, 3)).astype(np.float32)
    image[:3] = 0.0
    sensor = Sensor(**NULL, intrinsics_offset=np.zeros(3))
    coarse = downsample_camera(_camera(2 * W, 2 * H), 2)
    for camera in (_camera(), coarse):
        out = sensor.apply(mi.TensorXf(image), camera).numpy()
        assert np.array_equal(out.view(np.uint32), image.view(np.uint32))


def _mapped(camera: Camera, offset, turn=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Where, in the rendering's (block) pixels, the photographs' camera's pixel centres look:
    ``K R^T K'^-1`` written with the fine matrices of both cameras, in numpy (scipy's rotation)."""
    from scipy.spatial.transform import Rotation

    b = camera.block
    shift = -(b - 1) / (2.0 * b)
    S = np.array([[1.0 / b, 0.0, shift], [0.0, 1.0 / b, shift], [0.0, 0.0, 1.0]])
    k_fine = np.linalg.solve(S, camera.K)
    dcx, dcy, dfx = offset
    k_photo = k_fine.copy()
    k_photo[:2, :2] *= 1.0 + dfx / k_fine[0, 0]
    k_photo[0, 2] += dcx
    k_photo[1, 2] += dcy
    turned = Rotation.from_rotvec(turn).as_matrix().T
    mapping = camera.K @ turned @ np.linalg.inv(S @ k_photo)  # photograph block pixel -> rendering pixel
    v, u = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    p = np.einsum("ij,jhw->ihw", mapping, np.stack([u, v, np.ones_like(u)]))
    return p[0] / p[2], p[1] / p[2]


@pytest.mark.parametrize("block, skew, turn", [(1, 0.0, None), (1, 4.0, None), (2, 0.0, None),
                                               (1, 4.0, [0.03, -0.05, 0.04]), (2, 0.0, [0.03, -0.05, 0.04])])
def test_offset_resamples_where_the_photographs_camera_looks(block, skew, turn):
    """On an image linear in the pixel coordinates (which the cubic reproduces exactly), every
    pixel away from the border is the image's value where ``K R^T K'^-1`` sends it."""
    camera = _camera(W * block, H * block, skew)
    if block > 1:
        camera = downsample_camera(camera, block)
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    slopes = np.array([[0.3, 0.1, 2.0], [-0.2, 0.25, 9.0], [0.05, -0.4, 12.0]])  # per channel
    image = np.stack([a * u + c * v + d for a, c, d in slopes], axis=-1).astype(np.float32)
    offset = [1.7, -0.9, 2.5]
    out = Sensor(**NULL, intrinsics_offset=offset, camera_turn=turn).apply(mi.TensorXf(image), camera).numpy()
    x, y = _mapped(camera, offset, turn or (0.0, 0.0, 0.0))
    expected = np.stack([a * x + c * y + d for a, c, d in slopes], axis=-1)
    inside = (x >= 1) & (x <= W - 3) & (y >= 1) & (y <= H - 3)  # the cubic's 4x4 stencil inside
    assert inside.sum() > 0.5 * W * H
    np.testing.assert_allclose(out[inside], expected[inside], atol=2e-4)
    # Moved by about an (offset) pixel, not left in place.
    assert np.max(np.abs(out[inside] - image[inside])) > 0.3


def test_offset_matches_rendering_through_the_offset_camera(small_scene_dir):
    """The nominal camera's rendering, resampled, against the path tracer's rendering through
    the offset camera: the checkerboard's edges move alike (much closer than to the unmoved
    rendering)."""
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    camera = _camera(48, 36)
    offset = np.array([1.5, -1.0, 2.0])
    K = camera.K.copy()
    K[:2, :2] *= 1.0 + offset[2] / K[0, 0]
    K[:2, 2] += offset[:2]
    moved = compiled.render(Camera(K, camera.R, camera.t, 48, 36), spp=256, seed=1).numpy()
    plain = compiled.render(camera, spp=256, seed=1).numpy()
    compiled.set("sensor.intrinsics_offset", offset)
    try:
        resampled = compiled.render(camera, spp=256, seed=1).numpy()
    finally:
        compiled.set("sensor.intrinsics_offset", np.zeros(3))
    inner = (slice(3, -3), slice(3, -3))
    error = np.sqrt(np.mean((resampled[inner] - moved[inner]) ** 2))
    unmoved = np.sqrt(np.mean((plain[inner] - moved[inner]) ** 2))
    assert error < 0.35 * unmoved, (error, unmoved)


def test_turn_matches_rendering_through_the_turned_camera(small_scene_dir):
    """The nominal camera's rendering resampled by ``camera_turn`` against the path tracer's
    rendering through the turned camera (a large turn, so that the edges move by pixels)."""
    from scipy.spatial.transform import Rotation

    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    camera = _camera(48, 36)
    turn = np.array([0.03, -0.04, 0.02])
    Q = Rotation.from_rotvec(turn).as_matrix()
    moved = compiled.render(Camera(camera.K, Q @ camera.R, Q @ camera.t, 48, 36), spp=256, seed=1).numpy()
    plain = compiled.render(camera, spp=256, seed=1).numpy()
    compiled.set("sensor.camera_turn", turn)
    try:
        resampled = compiled.render(camera, spp=256, seed=1).numpy()
    finally:
        compiled.set("sensor.camera_turn", np.zeros(3))
    inner = (slice(4, -4), slice(4, -4))
    error = np.sqrt(np.mean((resampled[inner] - moved[inner]) ** 2))
    unmoved = np.sqrt(np.mean((plain[inner] - moved[inner]) ** 2))
    assert error < 0.35 * unmoved, (error, unmoved)


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    weights = mi.TensorXf(np.random.default_rng(0).uniform(0, 1, (H, W, 3)).astype(np.float32))
    return compiled, _camera(), weights


@pytest.mark.parametrize("name, value, step", [
    ("intrinsics_offset", [0.0, 0.0, 0.0], 0.05),   # what the score test sees
    ("intrinsics_offset", [0.7, -0.4, 1.5], 0.05),
    ("camera_turn", [0.0, 0.0, 0.0], 0.002),
    ("camera_turn", [0.02, -0.01, 0.03], 0.002),
])
def test_misalignment_gradients(setup, name, value, step):
    compiled, camera, weights = setup
    compiled.set(f"sensor.{name}", value)
    try:
        res = directional_gradient(compiled, camera, f"sensor.{name}", [1.0, -0.6, 0.8], step,
                                   weights, seeds=3, spp=4 * SPP, full=True)
    finally:
        compiled.set(f"sensor.{name}", np.zeros(3))
    assert_gradients_agree(*res, rel=0.02)


def test_effect_offers_itself_and_round_trips(small_scene_dir, tmp_path):
    scene = load_scene(small_scene_dir / "scene.toml")
    compiled = compile_scene(scene)
    offered = effects()["camera_misalignment"].candidates(scene, compiled)
    assert [(c.target, c.parameters) for c in offered] == [
        ("sensor", ("sensor.intrinsics_offset",)), ("cameras", ("sensor.camera_turn",))]
    for name, value in (("intrinsics_offset", [0.5, -0.25, 1.0]), ("camera_turn", [0.01, -0.02, 0.003])):
        again = load_scene(write_scene(scene, tmp_path / name / "scene.toml", {f"sensor.{name}": value}))
        np.testing.assert_allclose(getattr(again.sensor, name), value)
        # Either form in the scene file: neither is offered again.
        assert effects()["camera_misalignment"].candidates(again, compile_scene(again)) == []
