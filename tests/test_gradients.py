"""Gradients of images with respect to every kind of scene parameter match finite differences."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, compile_scene
from abs.scene import load_scene
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 32


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    return gradient_setup(small_scene_dir / "scene.toml", W, [0.0, 0.08, 0.32], [0.0, 0.05, 0.0], 30, 0)


@pytest.mark.parametrize("channel", [0, 1, 2])
def test_absorption_per_channel(setup, channel):
    compiled, camera, weights = setup
    res = directional_gradient(compiled, camera, "glass.absorption", np.eye(3)[channel], 0.5, weights)
    assert_gradients_agree(*res)


@pytest.mark.parametrize("mode", ["replay", "recorded"])
def test_absorption_by_reverse_mode(setup, mode):
    """The two reverse modes: path replay (fits' gradients) and a recorded render (dr.backward)."""
    compiled, camera, weights = setup
    res = directional_gradient(compiled, camera, "glass.absorption", [1.0, 0.5, 0.2], 0.5, weights,
                               mode=mode)
    assert_gradients_agree(*res)


@pytest.mark.parametrize("channel", [0, 1, 2])
def test_ior_per_channel(glass_scene_dir, channel):
    """Per-channel IOR of glass seen against the environment.

    Known limitation (docs/renderer.md): edges and shadows seen *through* the glass move with the
    IOR and their boundary terms are not reparameterised, so the scene here has none.
    """
    compiled = compile_scene(load_scene(glass_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.06, 0.3]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(W, H, np.radians(25)), R, t, W, H)
    weights = mi.TensorXf(np.random.default_rng(3).uniform(0, 1, (H, W, 3)).astype(np.float32))
    res = directional_gradient(compiled, camera, "glass.ior", np.eye(3)[channel], 0.02, weights,
                               seeds=6, spp=128, mode="tangents")
    assert_gradients_agree(*res, rel=0.1)


def test_ior_through_textured_scene(setup):
    """The IOR derivative fits use, with edges of the floor and the checkerboard seen through the
    glass (whose boundary terms forward mode leaves out), against finite differences of
    *independent* renders (no common random numbers, so the reference shares nothing with the
    estimator). Measured on a 48x48 view: forward mode 139 +- 10, the estimator 176 +- 3, and
    independent differences 166 +- 5 (h = 0.03) and 164 +- 4 (h = 0.04)."""
    compiled, camera, _ = setup
    x0 = compiled.get("glass.ior").copy()

    def render(ior, spp, seed):
        compiled.set("glass.ior", mi.Float(np.full(3, ior, np.float32)))
        return compiled.render(camera, spp=spp, seed=seed).numpy().astype(np.float64)

    try:
        # Weights along the image's change with IOR (a residual's direction), so that the
        # compared sums are large against their noise.
        weights = render(x0[1] + 0.03, 512, 101) - render(x0[1] - 0.03, 512, 102)
        compiled.set("glass.ior", mi.Float(np.full(3, x0[1], np.float32)))
        estimates = [float(np.sum(compiled.render_forward(camera, {"glass.ior": np.ones(3)}, spp=64,
                                                          seed=s)[1].numpy() * weights))
                     for s in range(6)]
        reference = [float(np.sum((render(x0[1] + 0.03, 128, 10 + s) - render(x0[1] - 0.03, 128, 20 + s))
                                  * weights)) / 0.06 for s in range(6)]
    finally:
        compiled.set("glass.ior", mi.Float(x0.astype(np.float32)))
    se = lambda v: float(np.std(v, ddof=1) / np.sqrt(len(v)))  # noqa: E731
    assert_gradients_agree(np.mean(estimates), se(estimates), np.mean(reference), se(reference),
                           rel=0.1)


def test_environment_scale(setup):
    compiled, camera, weights = setup
    assert_gradients_agree(*directional_gradient(compiled, camera, "environment.scale", [1.0], 0.05, weights))


def test_environment_rotation(setup):
    compiled, camera, weights = setup
    res = directional_gradient(compiled, camera, "environment.rotation", [1.0], 0.05, weights,
                               seeds=6, spp=128)
    assert_gradients_agree(*res, rel=0.1)


def test_diffuse_reflectance(setup):
    compiled, camera, weights = setup
    assert_gradients_agree(*directional_gradient(compiled, camera, "cloth.reflectance",
                                                 [0.3, 1.0, 0.5], 0.05, weights))


def test_texture_reflectance(setup):
    compiled, camera, weights = setup
    size = compiled.get("backdrop.reflectance").size
    direction = np.random.default_rng(1).uniform(0.5, 1.0, size)
    assert_gradients_agree(*directional_gradient(compiled, camera, "backdrop.reflectance",
                                                 direction, 0.05, weights))


@pytest.mark.parametrize("max_depth", [1, 2])
def test_pose_silhouette(silhouette_scene_dir, max_depth):
    """Object translation moves a silhouette: its boundary term comes from edge sampling.

    ``max_depth=1``: an unlit sphere in front of a uniform environment, so the whole gradient is
    the boundary term. ``max_depth=2``: the sphere is shaded (contrast 0.5 at the silhouette).
    """
    compiled = compile_scene(load_scene(silhouette_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.35]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(24, 24, np.radians(25)), R, t, 24, 24)
    # Ramps, so the boundary terms of opposite edges add rather than cancel.
    v, u = np.mgrid[0:24, 0:24] / 23.0
    weights = mi.TensorXf(np.repeat((u + 2 * v)[..., None], 3, axis=2).astype(np.float32))
    for direction in ([1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]):
        res = directional_gradient(compiled, camera, "sphere.pose", direction, 0.003, weights,
                                   max_depth=max_depth, spp=128, seeds=4)
        assert_gradients_agree(*res, rel=0.1)
    if max_depth == 1:
        without = directional_gradient(compiled, camera, "sphere.pose", [1, 0, 0, 0, 0, 0], 0.003,
                                       weights, max_depth=1, spp=16, seeds=2, edges=False,
                                       mode="recorded")
        assert without[0] == 0.0  # plain AD sees no gradient at all: the edge term is all of it
