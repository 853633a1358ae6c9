"""``environment.inverse_distance``: the environment map on a sphere of finite radius (parallax).

Exact at infinity (null value 0), geometrically right (the looked-up direction points at where the
ray leaves the sphere), and with derivatives equal to finite differences at infinity (where the
parallax is first order in 1/R) and at a finite distance."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from abs.render import compile_scene
from abs.scene import load_scene, write_scene
from conftest import assert_same_rendering
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 24


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    return gradient_setup(small_scene_dir / "scene.toml", W, [0.0, 0.1, 0.3], [0.0, 0.05, 0.0], 60, 2)


def _rays(n=1000, seed=0):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-0.4, 0.4, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d, mi.Point3f(o.T.astype(np.float32)), mi.Vector3f(d.T.astype(np.float32))


def test_at_infinity_lookup_is_bitwise_unchanged(setup):
    compiled, _, _ = setup
    env = compiled.environment
    assert float(env.inverse_distance[0]) == 0.0
    _, _, o, d = _rays()
    assert np.array_equal(np.array(env.hit_direction(o, d)), np.array(d))
    assert np.array_equal(np.array(env.eval(d, True, o)), np.array(env.eval(d)))


def test_at_infinity_render_is_unchanged(setup, monkeypatch):
    """The whole rendering equals one whose lookups ignore the ray origin (the model at infinity)."""
    compiled, camera, _ = setup
    image = compiled.render(camera, spp=4, seed=1, max_depth=4).numpy()
    env = compiled.environment
    at_infinity = type(env).eval
    monkeypatch.setattr(env, "eval", lambda d, active=True, origin=None: at_infinity(env, d, active))
    assert_same_rendering(image, compiled.render(camera, spp=4, seed=1, max_depth=4).numpy())


def test_lookup_points_at_the_sphere_hit(setup):
    compiled, _, _ = setup
    env = compiled.environment
    centre, radius = np.array([0.05, -0.02, 0.1]), 0.8
    saved = env.center
    env.center = mi.Point3f(*centre.tolist())
    env.inverse_distance = mi.Float(1.0 / radius)
    try:
        o_np, d_np, o, d = _rays(seed=1)
        q = np.array(env.hit_direction(o, d)).T
    finally:
        env.center, env.inverse_distance = saved, mi.Float(0.0)
    oc = o_np - centre
    b = np.sum(oc * d_np, axis=1)
    t = -b + np.sqrt(b * b - np.sum(oc * oc, axis=1) + radius ** 2)  # origins are inside
    np.testing.assert_allclose(q, (oc + t[:, None] * d_np) / radius, atol=2e-6)


@pytest.mark.parametrize("inverse_distance", [0.0, 2.0])
def test_inverse_distance_gradient(setup, inverse_distance):
    """Non-zero at 0 (infinity): the parallax is first order in 1/R."""
    compiled, camera, weights = setup
    compiled.set("environment.inverse_distance", [inverse_distance])
    try:
        res = directional_gradient(compiled, camera, "environment.inverse_distance", [1.0], 0.1,
                                   weights, seeds=4, spp=32)
    finally:
        compiled.set("environment.inverse_distance", [0.0])
    assert_gradients_agree(*res, rel=0.1)


def test_fields_round_trip(small_scene_dir, tmp_path):
    scene = load_scene(small_scene_dir / "scene.toml")
    text = (small_scene_dir / "scene.toml").read_text().replace(
        'scale = 1.0', 'scale = 1.0\ninverse_distance = 0.5\ncenter = [0.0, 0.1, 0.0]')
    (tmp_path / "scene.toml").write_text(text)
    for asset in ("sphere.ply", "floor.ply", "backdrop.obj", "env.exr", "checker.png"):
        (tmp_path / asset).write_bytes((small_scene_dir / asset).read_bytes())
    scene = load_scene(tmp_path / "scene.toml")
    assert scene.environment.inverse_distance == 0.5
    again = load_scene(write_scene(scene, tmp_path / "out" / "scene.toml",
                                   {"environment.inverse_distance": 1.5}))
    assert again.environment.inverse_distance == 1.5
    np.testing.assert_array_equal(again.environment.center, [0.0, 0.1, 0.0])
    compiled = compile_scene(again)
    np.testing.assert_allclose(compiled.get("environment.inverse_distance"), [1.5])
    assert dr.width(compiled.environment.inverse_distance) == 1
