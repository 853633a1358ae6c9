"""Glass surfaces lying on other surfaces are found, measured and announced by fits."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from abs import load_scene
from abs.render import compile_scene
from abs.render.contacts import TOLERANCE_M, _closest_on_triangles, coincident_area, coincident_surfaces
from tests.conftest import write_mesh

SQUARE = (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))


def test_closest_points_match_a_dense_search_of_each_triangle():
    rng = np.random.default_rng(3)
    a, b, c = (rng.normal(size=(200, 3)) for _ in range(3))
    p = 2 * rng.normal(size=(200, 3))
    q = _closest_on_triangles(p, a, b, c)
    u, v = np.meshgrid(np.linspace(0, 1, 301), np.linspace(0, 1, 301))
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    for i in range(0, 200, 7):
        grid = a[i] + u[:, None] * (b[i] - a[i]) + v[:, None] * (c[i] - a[i])
        dense = np.linalg.norm(grid - p[i], axis=1).min()
        exact = np.linalg.norm(q[i] - p[i])
        # On the triangle (barycentric weights in [0, 1]) and no farther than the grid's best.
        w = np.linalg.lstsq(np.stack([b[i] - a[i], c[i] - a[i]], 1), q[i] - a[i], rcond=None)[0]
        assert w.min() >= -1e-9 and w.sum() <= 1 + 1e-9
        assert exact <= dense + 1e-12 and dense - exact < 0.02 * np.linalg.norm(b[i] - a[i])


@pytest.mark.parametrize("offset_m, expected", [(0.0, 1.0), (0.5 * TOLERANCE_M, 1.0),
                                                (2 * TOLERANCE_M, 0.0), (1e-4, 0.0)])
def test_a_face_counts_when_it_lies_on_the_other_surface(offset_m, expected):
    vertices, faces = SQUARE
    big = (np.array([[-5, -5, offset_m], [5, -5, offset_m], [5, 5, offset_m], [-5, 5, offset_m]]),
           np.array([[0, 1, 2], [0, 2, 3]]))
    assert coincident_area(vertices, faces, *big) == pytest.approx(expected)


def test_a_sphere_touching_a_plane_at_one_point_lies_on_nothing():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.04)
    sphere.apply_translation([0, 0, -sphere.vertices[:, 2].min()])  # resting on z = 0
    plane = (np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
    assert sphere.vertices[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    assert coincident_area(sphere.vertices, sphere.faces, *plane) == 0.0


def _slab_scene(root, small_scene_dir, lift_m: float):
    """``small_scene_dir``'s scene with its glass sphere replaced by a 6 x 2 x 6 cm glass slab whose
    base is ``lift_m`` above the floor (y = 0)."""
    for name in ("floor.ply", "backdrop.obj", "env.exr", "checker.png"):
        (root / name).write_bytes((small_scene_dir / name).read_bytes())
    slab = trimesh.creation.box(extents=[0.06, 0.02, 0.06])
    slab.apply_translation([0, 0.01 + lift_m, 0])
    write_mesh(root / "sphere.ply", slab)
    (root / "scene.toml").write_text((small_scene_dir / "scene.toml").read_text())
    return root / "scene.toml"


def test_a_glass_slab_on_the_floor_is_found_and_a_lifted_one_is_not(small_scene_dir, tmp_path):
    (tmp_path / "on").mkdir(), (tmp_path / "lifted").mkdir()
    on = coincident_surfaces(compile_scene(load_scene(_slab_scene(tmp_path / "on", small_scene_dir, 0.0))))
    assert [(c.glass, c.other) for c in on] == [("sphere", "floor")]
    assert on[0].area_m2 == pytest.approx(0.06 * 0.06, rel=1e-4)  # the slab's whole base
    assert "lift sphere by 0.1 mm" in on[0].message()
    lifted = _slab_scene(tmp_path / "lifted", small_scene_dir, 1e-4)
    assert coincident_surfaces(compile_scene(load_scene(lifted))) == []
    # The repository's own glass: the sphere touches the cloth at a point, the bowl stands clear.
    default = Path("scenes/default").resolve()
    text = (default / "scene.toml").read_text()
    assert coincident_surfaces(compile_scene(load_scene(default / "scene.toml"))) == []
    bowl = text.replace('mesh = "sphere.ply"', f'mesh = "{(default / "bowl.ply").as_posix()}"')
    for asset in ("env.exr", "cloth.ply", "backdrop.ply", "checkerboard.png"):
        bowl = bowl.replace(f'"{asset}"', f'"{(default / asset).as_posix()}"')
    assert bowl != text
    (tmp_path / "bowl.toml").write_text(bowl)
    assert coincident_surfaces(compile_scene(load_scene(tmp_path / "bowl.toml"))) == []


def test_a_fit_on_such_a_scene_says_so_first(small_scene_dir, tmp_path):
    from abs.fitting import FitSettings, fit
    from abs.simulate import simulate_capture

    scene = _slab_scene(tmp_path, small_scene_dir, 0.0)
    simulate_capture(load_scene(scene), tmp_path / "capture", n_cameras=2, width=24, height=18, spp=8,
                     read_noise=0.003, seed=2)
    result = fit(scene, tmp_path / "capture", ["environment.scale"],
                 FitSettings(spp=4, max_iterations=1, refinement_steps=0))
    assert result.checks and result.checks[0].startswith("sphere's surface lies on floor's")
    assert json.loads(json.dumps(result.summary()))["checks"][0] == result.checks[0]


def test_one_large_triangle_beside_many_small_ones_still_finds_the_contact():
    # A floor of two large triangles plus a fine grid of small ones far away: the size classes
    # keep the search local, and the glass square on the floor is found whole.
    vertices, faces = SQUARE
    floor = [[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]]
    grid = np.array([[x, y, 3.0] for x in np.linspace(20, 21, 40) for y in np.linspace(20, 21, 40)])
    small = np.array([[i, i + 1, i + 40] for i in range(len(grid) - 41) if (i + 1) % 40])
    other_v = np.vstack([floor, grid])
    other_f = np.vstack([[[0, 1, 2], [0, 2, 3]], small + 4])
    assert coincident_area(vertices, faces, other_v, other_f) == pytest.approx(1.0)
    assert coincident_area(vertices + [0, 0, 1e-3], faces, other_v, other_f) == 0.0
