"""A rendered view lines up with the OpenCV camera model to a fraction of a pixel.

Small white spheres at known 3D points are rendered against a black backdrop with an asymmetric
calibration (fx != fy, off-centre principal point, rotated camera); the intensity centroid of each
blob must land on the projection of its centre.
"""

from __future__ import annotations

import numpy as np
import trimesh

from abs.camera.pinhole import look_at, project
from abs.io.images import write_exr
from abs.render import Camera, compile_scene
from abs.scene import load_scene

POINTS = np.array([[0.0, 0.0, 0.0], [0.06, 0.03, 0.01], [-0.05, -0.02, 0.03], [0.03, -0.05, -0.02]])


def test_points_project_where_rendered(tmp_path):
    objects = []
    for i, p in enumerate(POINTS):
        ball = trimesh.creation.icosphere(subdivisions=3, radius=0.0025)
        ball.apply_translation(p)
        ball.export(tmp_path / f"ball{i}.ply")
        objects.append(f'[[objects]]\nname = "ball{i}"\nmesh = "ball{i}.ply"\nmaterial = "white"\n')
    wall = trimesh.Trimesh([[-1, -1, -0.3], [1, -1, -0.3], [1, 1, -0.3], [-1, 1, -0.3]],
                           [[0, 1, 2], [0, 2, 3]], process=False)
    wall.export(tmp_path / "wall.ply")
    write_exr(tmp_path / "env.exr", np.ones((8, 16, 3), np.float32))
    (tmp_path / "scene.toml").write_text(
        '[environment]\nfile = "env.exr"\n\n[materials.white]\ntype = "diffuse"\nreflectance = 1.0\n\n'
        '[materials.black]\ntype = "diffuse"\nreflectance = 0.0\n\n' + "\n".join(objects)
        + '\n[[objects]]\nname = "wall"\nmesh = "wall.ply"\nmaterial = "black"\n')
    compiled = compile_scene(load_scene(tmp_path / "scene.toml"))

    width, height = 120, 90
    K = np.array([[210.0, 0.0, 63.3], [0.0, 190.0, 41.7], [0.0, 0.0, 1.0]])
    R, t = look_at(np.array([0.05, 0.04, 0.45]), np.array([0.0, 0.0, 0.0]))
    image = compiled.render(Camera(K, R, t, width, height), spp=256, max_depth=2).numpy().mean(axis=2)

    expected = project(K, R, t, POINTS)
    v, u = np.mgrid[0:height, 0:width]
    for (eu, ev) in expected:
        window = (np.abs(u - eu) < 5) & (np.abs(v - ev) < 5)
        w = image * window
        assert w.sum() > 1.0, f"no blob near ({eu:.1f}, {ev:.1f})"
        cu, cv = (w * u).sum() / w.sum(), (w * v).sum() / w.sum()
        assert abs(cu - eu) < 0.1 and abs(cv - ev) < 0.1, f"blob at ({cu:.3f}, {cv:.3f}), projected ({eu:.3f}, {ev:.3f})"
