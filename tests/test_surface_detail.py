"""``normal_smoothing`` of a dielectric (the ``surface_detail`` effect): exact at zero, the
normals it names (against neighbours found by trimesh), composed with a pose, derivatives equal
to finite differences, read and written through the scene file."""

from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest
import trimesh

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.diagnosis.effects import effects
from abs.render import Camera, compile_scene
from abs.scene import load_scene, write_scene
from conftest import assert_same_rendering, make_noisy_sphere
from gradcheck import assert_gradients_agree, directional_gradient, gradient_setup

W = H = 32
NAME = "glass.normal_smoothing"


#: Radial noise of the spheres' vertices (m): on a clean icosphere the normals' differences from
#: their neighbours' mean are nearly along the normal, and smoothing them changes little.
NOISE_M = 0.001


def _noisy(root, scene_dir):
    """``scene_dir``'s files in ``root``, its sphere with noisy vertices."""
    for f in scene_dir.iterdir():
        (root / f.name).write_bytes(f.read_bytes())
    make_noisy_sphere(root / "sphere.ply", NOISE_M)
    return root


@pytest.fixture(scope="module")
def setup(small_scene_dir, tmp_path_factory):
    root = _noisy(tmp_path_factory.mktemp("noisy_small"), small_scene_dir)
    return gradient_setup(root / "scene.toml", W, [0.0, 0.08, 0.32], [0.0, 0.05, 0.0], 30, 0)


def _normals(compiled, obj="sphere") -> np.ndarray:
    return np.array(compiled.params[f"{compiled.shape_ids[obj]}.vertex_normals"]).reshape(-1, 3)


def test_zero_smoothing_is_the_scene_as_loaded(setup):
    compiled, camera, _ = setup
    loaded = _normals(compiled).copy()
    reference = compiled.render(camera, spp=4, seed=2).numpy()
    compiled.set(NAME, [0.0])
    assert np.array_equal(_normals(compiled).view(np.uint32), loaded.view(np.uint32))
    assert_same_rendering(compiled.render(camera, spp=4, seed=2).numpy(), reference)


def test_smoothing_moves_each_normal_towards_its_neighbours_mean(setup, small_scene_dir):
    """``n + s (m - n)``, ``m`` the mean of the normals of the vertices that share an edge with it
    (trimesh's neighbours, not abs's), with and without a pose turning the result."""
    compiled, camera, _ = setup
    loaded = _normals(compiled).astype(np.float64)
    faces = np.array(compiled.params[f"{compiled.shape_ids['sphere']}.faces"]).reshape(-1, 3)
    mesh = trimesh.Trimesh(np.zeros((len(loaded), 3)), faces, process=False)
    mean = np.array([loaded[nb].mean(axis=0) for nb in mesh.vertex_neighbors])
    try:
        compiled.set(NAME, [0.6])
        np.testing.assert_allclose(_normals(compiled), loaded + 0.6 * (mean - loaded), atol=1e-6)
        compiled.set("sphere.pose", [0.0, 0.0, 0.0, 0.0, 0.0, 0.3])
        c, s = np.cos(0.3), np.sin(0.3)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        np.testing.assert_allclose(_normals(compiled), (loaded + 0.6 * (mean - loaded)) @ turn.T, atol=1e-6)
        assert np.abs(mean - loaded).max() > 1e-2  # moved by 10^4 times the tolerance
    finally:
        compiled.set("sphere.pose", np.zeros(6))
        compiled.set(NAME, [0.0])
    np.testing.assert_array_equal(_normals(compiled), loaded.astype(np.float32))


@pytest.mark.parametrize("value", [0.0, -0.5])
def test_forward_mode_against_finite_differences(glass_scene_dir, tmp_path, value):
    """Glass seen against the environment only (no edges seen through it, whose boundary terms
    forward mode leaves out; docs/renderer.md), at the null value and away from it."""
    compiled = compile_scene(load_scene(_noisy(tmp_path, glass_scene_dir) / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.06, 0.3]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(W, H, np.radians(25)), R, t, W, H)
    # Weights along the image's change (a residual's direction): random ones leave the weighted
    # change below the finite differences' noise at -0.5.
    change = []
    for step in (0.1, -0.1):
        compiled.set(NAME, [value + step])
        change.append(compiled.render(camera, spp=256, seed=7).numpy())
    weights = mi.TensorXf((change[0] - change[1]).astype(np.float32))
    compiled.set(NAME, [value])
    res = directional_gradient(compiled, camera, NAME, [1.0], 0.05, weights, seeds=6, spp=64,
                               mode="tangents")
    assert_gradients_agree(*res, rel=0.1)


def test_fits_derivative_against_independent_differences(setup):
    """The derivative fits use (central differences of step ``difference_step`` with common
    random numbers, since the checkerboard's edges seen through the glass move), against
    differences of independent renders over the same step, weighted along the image's change."""
    compiled, camera, _ = setup

    def render(s, spp, seed):
        compiled.set(NAME, [s])
        return compiled.render(camera, spp=spp, seed=seed).numpy().astype(np.float64)

    h = compiled.specs[NAME].difference_step
    try:
        weights = render(h, 256, 101) - render(-h, 256, 102)
        compiled.set(NAME, [0.0])
        estimates = [float(np.sum(compiled.render_forward(camera, {NAME: [1.0]}, spp=32, seed=s)[1]
                                  .numpy() * weights)) for s in range(6)]
        reference = [float(np.sum((render(h, 64, 10 + s) - render(-h, 64, 20 + s)) * weights)) / (2 * h)
                     for s in range(6)]
    finally:
        compiled.set(NAME, [0.0])
    se = lambda v: float(np.std(v, ddof=1) / np.sqrt(len(v)))  # noqa: E731
    assert_gradients_agree(np.mean(estimates), se(estimates), np.mean(reference), se(reference), rel=0.1)


def test_effect_offers_itself_and_round_trips(small_scene_dir, tmp_path):
    scene = load_scene(small_scene_dir / "scene.toml")
    (candidate,) = effects()["surface_detail"].candidates(scene, compile_scene(scene))
    assert candidate.parameters == (NAME,)
    path = write_scene(scene, tmp_path / "written" / "scene.toml", {NAME: 0.35})
    again = load_scene(path)
    assert again.materials["glass"].normal_smoothing == pytest.approx(0.35)
    assert effects()["surface_detail"].candidates(again, compile_scene(again)) == []
    # A scene file's non-zero value reaches the meshes when it is compiled. Equal to float
    # round-off, not bitwise: the neighbours' means are sums scattered from parallel threads, whose
    # order can change the last bit (a CI run: 83 of 1926 components up to 9e-8 apart).
    fresh = compile_scene(scene)
    fresh.set(NAME, [0.35])
    np.testing.assert_allclose(_normals(compile_scene(again)), _normals(fresh), rtol=0, atol=1e-6)
