"""``[environment] probe_fresnel`` (the ``probe_fresnel`` effect): exact at zero, the factor it
names (the exact Fresnel reflectance of the ball's metal at the ball's angle of incidence,
against abs.probe's numpy conductor Fresnel), derivatives equal to finite differences, read,
validated and written through the scene file."""

from __future__ import annotations

import re

import mitsuba as mi
import numpy as np
import pytest

from abs.diagnosis.effects import effects
from abs.errors import SceneError
from abs.render.environment import Environment
from abs.scene import load_scene, write_scene
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 32
NAME = "environment.probe_fresnel"


def _map() -> np.ndarray:
    return np.random.default_rng(0).uniform(0.1, 2.0, (16, 32, 3)).astype(np.float32)


def _directions(n=500) -> np.ndarray:
    d = np.random.default_rng(1).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _eval(env: Environment, d: np.ndarray) -> np.ndarray:
    v = mi.Vector3f(*(mi.Float(d[:, i].astype(np.float32)) for i in range(3)))
    return np.array(env.eval(v)).T.reshape(-1, 3)


def test_zero_changes_no_bit():
    """At c = 0 every lookup is the plain map's (the factor is 1 exactly), for any probe view."""
    d = _directions()
    plain = Environment(_map(), scale=1.3, rotation=0.4)
    for view in ([0.0, 0.0, 1.0], [0.3, -0.8, 0.2]):
        zero = Environment(_map(), scale=1.3, rotation=0.4, probe_fresnel=[0.0] * 3, probe_view=view)
        assert np.array_equal(_eval(zero, d).view(np.uint32), _eval(plain, d).view(np.uint32))


@pytest.mark.parametrize("metal", [None, ([0.2, 0.15, 1.2], [3.4, 2.6, 2.0])], ids=["chromium", "other"])
def test_light_is_divided_by_the_balls_fresnel_factor(metal):
    from abs.probe.fresnel import conductor_reflectance
    from abs.scene.scene import CHROMIUM_IOR_RGB, CHROMIUM_K_RGB

    d = _directions(2000)
    view = np.array([0.3, -0.8, 0.2])
    c = np.array([1.0, 0.6, 0.3])
    eta, k = (CHROMIUM_IOR_RGB, CHROMIUM_K_RGB) if metal is None else metal
    plain = Environment(_map(), rotation=0.4)
    probe = Environment(_map(), rotation=0.4, probe_fresnel=c, probe_view=view,
                        **({} if metal is None else {"probe_ior": eta, "probe_k": k}))
    # The map's own frame: rotation about +y by 0.4 (to_world is the identity).
    co, si = np.cos(0.4), np.sin(0.4)
    local = d @ np.array([[co, 0.0, si], [0.0, 1.0, 0.0], [-si, 0.0, co]])
    cos_i = np.sqrt((1.0 + local @ (view / np.linalg.norm(view))) / 2.0)
    excess = conductor_reflectance(cos_i, eta, k) / conductor_reflectance(np.ones(1), eta, k)[0] - 1.0
    expected = _eval(plain, d) / (1.0 + c * excess)
    np.testing.assert_allclose(_eval(probe, d), expected, rtol=1e-4)
    ratio = expected / _eval(plain, d)
    # Near the opposite of the probe camera (the ball's rim) the light loses a fifth or more:
    # the comparison above is not of two nearly equal maps. Chromium's reflectance dips below
    # its normal-incidence value, so over the band between the light gains a few per cent (red
    # most): not Schlick's monotone shape.
    assert np.min(ratio) < 0.8
    if metal is None:
        assert np.min(ratio) < 0.6 and np.max(ratio[:, 0]) > 1.05


@pytest.fixture(scope="module")
def setup(small_scene_dir, tmp_path_factory):
    """The small scene with its probe camera below the ball, so the map's corrected part is the
    sky that lights the scene (from +z it would be behind the backdrop)."""
    root = tmp_path_factory.mktemp("probe_scene")
    for f in small_scene_dir.iterdir():
        (root / f.name).write_bytes(f.read_bytes())
    text = (root / "scene.toml").read_text()
    (root / "scene.toml").write_text(text.replace("[environment]\n", "[environment]\nprobe_view = [0.0, -1.0, 0.2]\n", 1))
    return gradient_setup(root / "scene.toml", W, [0.0, 0.08, 0.32], [0.0, 0.05, 0.0], 30, 0)


@pytest.mark.parametrize("value", [[0.0, 0.0, 0.0], [0.8, 0.5, 0.2]])
def test_probe_fresnel_gradient(setup, value):
    compiled, camera, weights = setup
    compiled.set(NAME, value)
    try:
        res = directional_gradient(compiled, camera, NAME, [1.0, 0.6, 0.3], 0.05, weights)
    finally:
        compiled.set(NAME, [0.0, 0.0, 0.0])
    assert_gradients_agree(*res)


def test_effect_offers_itself_round_trips_and_validates(small_scene_dir, tmp_path):
    from abs.render import compile_scene

    scene = load_scene(small_scene_dir / "scene.toml")
    (candidate,) = effects()["probe_fresnel"].candidates(scene, compile_scene(scene))
    assert candidate.parameters == (NAME,)
    again = load_scene(write_scene(scene, tmp_path / "written" / "scene.toml", {NAME: [0.7, 0.6, 0.5]}))
    np.testing.assert_allclose(again.environment.probe_fresnel, [0.7, 0.6, 0.5])
    np.testing.assert_allclose(again.environment.probe_view, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(again.environment.probe_ior, [3.28, 3.05, 2.37])  # chromium
    np.testing.assert_allclose(again.environment.probe_k, [3.31, 3.31, 3.14])
    assert effects()["probe_fresnel"].candidates(again, compile_scene(again)) == []
    text = (small_scene_dir / "scene.toml").read_text()
    for line, message in [("probe_view = [0.0, 0.0, 0.0]", "environment.probe_view: expected a direction"),
                          ("probe_fresnel = -1.0", "environment.probe_fresnel: all entries must be >= -0.9"),
                          ("probe_k = [3.0, -1.0, 3.0]", "environment.probe_k: all entries must be >= 0")]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text.replace("[environment]\n", f"[environment]\n{line}\n", 1))
        for f in small_scene_dir.iterdir():
            if f.name != "scene.toml":
                (tmp_path / f.name).write_bytes(f.read_bytes())
        with pytest.raises(SceneError, match=re.escape(message)):
            load_scene(bad)
