"""The renderer's three ways of differentiating agree with each other, sample for sample.

Forward mode (tangents carried inside the path loop) and path replay (reverse mode) see the same
samples for the same seed, so for every parameter that replay can differentiate, the replayed
gradient of ``sum(w * image)`` must equal the forward-mode directional derivatives contracted with
``w`` to float round-off; both are checked against finite differences in ``test_gradients.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, compile_scene
from abs.scene import load_scene

W, H, SPP = 24, 18, 8


@pytest.fixture(scope="module")
def scene(small_scene_dir):
    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.08, 0.32]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(W, H, np.radians(30)), R, t, W, H)
    weights = np.random.default_rng(0).uniform(-1, 1, (H, W, 3))
    return compiled, camera, weights


@pytest.mark.parametrize("name", ["glass.absorption", "environment.scale", "environment.rotation",
                                  "cloth.reflectance", "backdrop.reflectance"])
def test_replay_equals_forward_mode(scene, name):
    compiled, camera, weights = scene
    size = compiled.get(name).size
    # Textures have many scalars: compare along a few random directions instead of every column.
    directions = np.eye(size) if size <= 3 else np.random.default_rng(1).normal(size=(3, size))
    image, gradient = compiled.render_backward(camera, weights, [name], spp=SPP, seed=4, max_depth=6)
    for direction in directions:
        primal, derivative = compiled.render_forward(camera, {name: direction}, spp=SPP, seed=4,
                                                     max_depth=6)
        forward = float(np.sum(derivative.numpy() * weights))
        replayed = float(gradient[name] @ direction)
        assert replayed == pytest.approx(forward, rel=2e-3, abs=1e-6 * np.abs(weights).sum())
        np.testing.assert_allclose(primal.numpy(), image, rtol=1e-5, atol=1e-6)


def test_primal_render_is_the_forward_renders_image(scene):
    compiled, camera, _ = scene
    plain = compiled.render(camera, spp=SPP, seed=9).numpy()
    primal, _ = compiled.render_forward(camera, {"glass.absorption": [1.0, 0.0, 0.0]}, spp=SPP, seed=9)
    np.testing.assert_allclose(primal.numpy(), plain, rtol=1e-5, atol=1e-6)


def test_replay_refuses_parameters_that_move_paths(scene):
    compiled, camera, weights = scene
    with pytest.raises(ValueError, match="glass.ior move light paths"):
        compiled.render_backward(camera, weights, ["glass.ior"], spp=1)
    # The scene is left as it was.
    assert not np.isnan(compiled.render(camera, spp=1).numpy()).any()


@pytest.mark.parametrize("name", ["glass.absorption", "glass.ior", "cloth.reflectance"])
def test_separable_channels_share_one_forward_render(scene, name):
    """Channel c of the derivative along (1, 1, 1) is the derivative along e_c: the fits render
    one Jacobian pass for all three channels of such a parameter (FitProblem.column_passes).

    Sample for sample in forward mode (``differences=False``). An IOR's fitted columns come from
    central differences, where moving one channel alone splits the paths at the glass and moving
    all three together does not: the two then agree in expectation, not sample for sample."""
    compiled, camera, _ = scene
    assert compiled.specs[name].separable_channels
    others = {"glass.ior": np.zeros(3)} if name != "glass.ior" else {}  # the same paths in each
    _, together = compiled.render_forward(camera, {name: np.ones(3), **others}, spp=SPP, seed=2,
                                          max_depth=6, differences=False)
    together = together.numpy()
    for c in range(3):
        _, alone = compiled.render_forward(camera, {name: np.eye(3)[c], **others}, spp=SPP, seed=2,
                                           max_depth=6, differences=False)
        alone = alone.numpy()
        np.testing.assert_allclose(together[..., c], alone[..., c], rtol=1e-4,
                                   atol=1e-5 * np.abs(alone).max())
        assert np.abs(alone[..., [k for k in range(3) if k != c]]).max() <= 1e-6 * np.abs(alone).max()


def test_forward_renders_counts_the_difference_renders(scene, monkeypatch):
    """Render accounting: an IOR's Jacobian pass renders at p and p +- h (three renders); two when
    the caller has the image at p (a recording), or when a bound makes the difference one-sided.
    Each count is the number of renders made, and skipping p's render changes no derivative."""
    compiled, camera, _ = scene
    assert compiled.forward_renders({"glass.absorption": np.ones(3), "glass.ior": np.zeros(3)}) == 1
    assert compiled.forward_renders({"glass.ior": np.ones(3)}, differences=False) == 1
    made = []
    render = compiled.render
    monkeypatch.setattr(compiled, "render", lambda *a, **k: made.append(1) or render(*a, **k))
    ior = compiled.get("glass.ior").copy()
    lower = compiled.specs["glass.ior"].lower
    derivatives = {}
    try:
        for at, needed, count in ((ior, True, 3), (ior, False, 2), (np.full(3, lower), True, 2),
                                  (np.full(3, lower), False, 2)):
            compiled.set("glass.ior", at)
            tangents = {"glass.ior": np.ones(3)}
            assert compiled.forward_renders(tangents, image_needed=needed) == count
            made.clear()
            image, derivative = compiled.render_forward(camera, tangents, spp=SPP, seed=4,
                                                        max_depth=6, image_needed=needed)
            assert len(made) == count
            assert (image is None) == (not needed and count == 2 and at is ior)
            derivatives[(at is ior, needed)] = derivative.numpy()
    finally:
        compiled.set("glass.ior", ior)
    np.testing.assert_array_equal(derivatives[(True, True)], derivatives[(True, False)])
    np.testing.assert_array_equal(derivatives[(False, True)], derivatives[(False, False)])
    assert np.abs(derivatives[(True, True)]).max() > 0
