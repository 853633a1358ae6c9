"""``[environment] orientation``: a rotation vector turning the map about all three axes. Exact
at zero, the rotation it names (against an independent Rodrigues matrix, and equal to
``rotation`` about +y), derivatives equal to finite differences, read and written through the
scene file."""

from __future__ import annotations

import re

import mitsuba as mi
import numpy as np
import pytest

from abs.errors import SceneError
from abs.render.environment import Environment, _rotation_y
from abs.scene import load_scene, write_scene
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 32


def _map() -> np.ndarray:
    return np.random.default_rng(0).uniform(0.1, 2.0, (16, 32, 3)).astype(np.float32)


def _directions(n=500) -> np.ndarray:
    d = np.random.default_rng(1).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _vector(d: np.ndarray) -> mi.Vector3f:
    return mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3)))


def _eval(env: Environment, d: np.ndarray) -> np.ndarray:
    return np.array(env.eval(_vector(d))).T.reshape(-1, 3)


def _rodrigues(r) -> np.ndarray:
    """Rotation matrix of rotation vector ``r``, written out here (not abs's)."""
    r = np.asarray(r, float)
    t = np.linalg.norm(r)
    x, y, z = r / t
    c, s, C = np.cos(t), np.sin(t), 1 - np.cos(t)
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


def test_zero_orientation_changes_no_bit():
    """The frame at orientation 0 is the frame without it, entry for entry."""
    base = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0, 0, 0, 1.0]])
    env = Environment(_map(), to_world=base, rotation=0.37)
    d = _vector(_directions())
    plain = (_rotation_y(env.rotation) @ mi.Matrix3f(base[:3, :3].astype(np.float32))).T @ d
    local = env.to_local(d)
    for a, b in zip(local, plain):
        assert np.array_equal(np.array(a).view(np.uint32), np.array(b).view(np.uint32))


def test_orientation_turns_the_map_by_its_rotation_vector():
    """Light from ``d`` under orientation ``r`` is the unturned map's light from ``R(r)^T d``;
    a rotation vector along +y is ``rotation`` by its length."""
    d = _directions()
    plain = Environment(_map(), rotation=0.2)
    r = np.array([0.3, -0.5, 0.4])
    turned = Environment(_map(), rotation=0.2, orientation=r)
    np.testing.assert_allclose(_eval(turned, d), _eval(plain, d @ _rodrigues(r)), rtol=2e-4, atol=2e-4)
    about_y = Environment(_map(), rotation=0.2, orientation=[0.0, 0.45, 0.0])
    np.testing.assert_allclose(_eval(about_y, d), _eval(Environment(_map(), rotation=0.65), d),
                               rtol=2e-4, atol=2e-4)
    # The Mitsuba emitter it exports is turned alike (interoperability with stock integrators).
    def frame(env):
        return np.array(env.mitsuba_dict()["to_world"].matrix, np.float64)[:3, :3]

    np.testing.assert_allclose(frame(turned), _rodrigues(r) @ frame(plain), atol=1e-6)


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    return gradient_setup(small_scene_dir / "scene.toml", W, [0.0, 0.08, 0.32], [0.0, 0.05, 0.0], 30, 0)


@pytest.mark.parametrize("value, direction, mode", [
    ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], "forward"),    # tilt about x at the null value
    ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], "forward"),    # about z (the view axis, roughly)
    ([0.1, -0.2, 0.15], [0.6, 0.3, -0.7], "forward"),  # away from it
    ([0.0, 0.0, 0.0], [0.5, 0.2, 0.8], "replay"),     # what fits' gradients use
])
def test_orientation_gradient(setup, value, direction, mode):
    compiled, camera, weights = setup
    compiled.set("environment.orientation", value)
    try:
        res = directional_gradient(compiled, camera, "environment.orientation", direction, 0.05,
                                   weights, seeds=6, spp=128, mode=mode)
    finally:
        compiled.set("environment.orientation", [0.0, 0.0, 0.0])
    assert_gradients_agree(*res, rel=0.1)


def test_orientation_round_trip_and_errors(small_scene_dir, tmp_path):
    scene = load_scene(small_scene_dir / "scene.toml")
    value = [0.05, -0.1, 0.02]
    again = load_scene(write_scene(scene, tmp_path / "written" / "scene.toml",
                                   {"environment.orientation": value}))
    np.testing.assert_allclose(again.environment.orientation, value)

    for asset in ("sphere.ply", "floor.ply", "backdrop.obj", "env.exr", "checker.png"):
        (tmp_path / asset).write_bytes((small_scene_dir / asset).read_bytes())
    text = (small_scene_dir / "scene.toml").read_text()
    for line, message in [("orientation = 0.1", "environment.orientation: expected shape [3], got []"),
                          ("orientation = [0.1, 0.2]", "environment.orientation: expected shape [3], got [2]"),
                          ('orientation = [0.1, "x", 0.0]', "environment.orientation: expected numbers")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace("[environment]\n", f"[environment]\n{line}\n"))
        with pytest.raises(SceneError, match=re.escape(message)) as info:
            load_scene(bad)
        assert str(bad) in str(info.value)
