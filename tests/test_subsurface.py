"""``subsurface`` of the ``diffuse`` material: the plain Lambertian surface exactly at 0, a Gaussian
blur of the surface's appearance of the stated width (closed form across a reflectance edge), and
score-function gradients equal to finite differences.

Not checked here: the gradient where shadows and caustics move (unbiased by construction, but the
score-function estimator needs ~100x the samples of a finite difference to resolve it there)."""

from __future__ import annotations

from math import erf

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from abs.errors import SceneError
from abs.render import Camera, PathTracer, compile_scene
from abs.scene import load_scene, write_scene
from conftest import assert_same_rendering
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 24


@pytest.fixture(scope="module")
def setup(small_scene_dir):
    return gradient_setup(small_scene_dir / "scene.toml", W, [0.0, 0.15, 0.3], [0.0, 0.02, 0.0], 40, 4)


def test_zero_subsurface_is_plain_diffuse(setup):
    compiled, camera, _ = setup
    assert compiled.get("cloth.subsurface") == [0.0] and compiled.subsurface() == []
    image = compiled.render(camera, spp=4, seed=2, max_depth=4).numpy()
    plain = PathTracer(max_depth=4).render(compiled.mitsuba_scene, compiled.environment, camera, 4, 2)
    assert_same_rendering(image, plain.numpy())


@pytest.fixture(scope="module")
def edge_scene(tmp_path_factory):
    """A 20 cm floor whose reflectance steps from 0.2 (x < 0) to 0.8 (x > 0), under a uniform
    white environment (radiance 1), so that the radiance leaving it equals its reflectance."""
    import trimesh

    from abs.io.images import write_exr

    root = tmp_path_factory.mktemp("edge_scene")
    write_exr(root / "white.exr", np.ones((8, 16, 3), np.float32))
    texture = np.full((4, 512, 3), 0.2, np.float32)
    texture[:, 256:] = 0.8
    write_exr(root / "step.exr", texture)
    floor = trimesh.Trimesh(vertices=[[-0.1, 0, -0.1], [0.1, 0, -0.1], [0.1, 0, 0.1], [-0.1, 0, 0.1]],
                            faces=[[0, 2, 1], [0, 3, 2]], process=False)
    floor.visual = trimesh.visual.TextureVisuals(uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
    floor.export(root / "floor.obj")
    (root / "scene.toml").write_text("""
[environment]
file = "white.exr"

[materials.cloth]
type = "diffuse"
reflectance = "step.exr"
subsurface = 0.01

[[objects]]
name = "floor"
mesh = "floor.obj"
material = "cloth"
""")
    return root


def test_spread_blurs_a_reflectance_edge_by_sigma(edge_scene):
    compiled = compile_scene(load_scene(edge_scene / "scene.toml"))
    sigma, height, width = 0.01, 0.3, 32
    # 3.75 mm pixels: the view (12 cm) stays inside the floor (20 cm) beyond 3 sigma.
    K = np.array([[80.0, 0, (width - 1) / 2], [0, 80.0, 3.5], [0, 0, 1]])
    # Looking straight down: image x along world +x, image y along world +z.
    R = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    t = -R @ np.array([0.0, height, 0.0])
    image = compiled.render(Camera(K, R, t, width, 8), spp=256, seed=0, max_depth=2).numpy()
    profile = image[..., 1].mean(axis=0)
    # Expected: reflectance blurred by a Gaussian of sigma, then by the tent pixel filter.
    metres_per_px = height / K[0, 0]
    u = np.arange(width)[:, None] + np.linspace(-1, 1, 201)[None, :]
    tent = 1 - np.abs(np.linspace(-1, 1, 201))
    blurred = 0.2 + 0.6 * 0.5 * (1 + np.vectorize(erf)((u - K[0, 2]) * metres_per_px / (sigma * np.sqrt(2))))
    expected = (blurred * tent).sum(axis=1) / tent.sum()
    assert np.abs(profile - expected).max() < 0.02, np.c_[profile, expected]
    # and clearly not the sharp edge: the model did blur
    sharp = 0.2 + 0.6 * (np.arange(width) > K[0, 2])
    assert np.abs(profile - sharp).max() > 0.15


def test_subsurface_gradient_across_an_edge(edge_scene):
    """The blurred edge spreads as sigma grows: darker on the bright side, brighter on the dark."""
    compiled = compile_scene(load_scene(edge_scene / "scene.toml"))
    width = 32
    K = np.array([[80.0, 0, (width - 1) / 2], [0, 80.0, 3.5], [0, 0, 1]])
    R = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    camera = Camera(K, R, -R @ np.array([0.0, 0.3, 0.0]), width, 8)
    side = np.where(np.arange(width) < K[0, 2], 1.0, -1.0)
    weights = mi.TensorXf(np.broadcast_to(side[None, :, None], (8, width, 3)).astype(np.float32).copy())
    res = directional_gradient(compiled, camera, "cloth.subsurface", [1.0], 0.002, weights,
                               seeds=4, spp=64, max_depth=2, full=True)
    assert_gradients_agree(*res, rel=0.1)


def test_subsurface_field(small_scene_dir, tmp_path):
    text = (small_scene_dir / "scene.toml").read_text()
    for asset in ("sphere.ply", "floor.ply", "backdrop.obj", "env.exr", "checker.png"):
        (tmp_path / asset).write_bytes((small_scene_dir / asset).read_bytes())
    bad = text.replace('reflectance = [0.7, 0.7, 0.65]', 'reflectance = [0.7, 0.7, 0.65]\nsubsurface = -1e-3')
    (tmp_path / "scene.toml").write_text(bad)
    with pytest.raises(SceneError, match="materials.cloth.subsurface: must be >= 0"):
        load_scene(tmp_path / "scene.toml")
    (tmp_path / "scene.toml").write_text(text)
    scene = load_scene(tmp_path / "scene.toml")
    again = load_scene(write_scene(scene, tmp_path / "out" / "scene.toml", {"cloth.subsurface": 0.004}))
    assert again.materials["cloth"].subsurface_m == 0.004
    assert again.materials["backdrop"].subsurface_m == 0.0
    compiled = compile_scene(again)
    assert compiled.get("cloth.subsurface") == pytest.approx([0.004])
    assert len(compiled.subsurface()) == 1
    assert dr.width(compiled.subsurface()[0][1]) == 1
