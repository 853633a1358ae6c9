"""A background with regions of known materials, for proving micropolygon labelling on
photographs rendered by abs (tests, benchmarks/reassembly_labels.py, the notebook).

The background is the default scene's set-up cut down: a floor (y = 0, x and z in
[-0.15, 0.15] m) and a back wall (z = -0.15 m, x in [-0.15, 0.15], y in [0, 0.2] m). The floor
holds three regions: a red strip (x < -0.03 m), a blue disc (centre (0.06, 0, 0.04) m, radius
0.05 m) and green elsewhere; the wall is light grey. The rendered meshes are grids of
``CELL_M`` squares, each square given the region of its centre, so the truth of any point is the
region of the square it lies in (:func:`region_of`), exactly what was rendered. Lit by the
default scene's environment map.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from abs.camera.pinhole import intrinsics_from_fov, look_at

__all__ = ["CELL_M", "REGIONS", "region_of", "truth_scene", "scanned_background", "truth_cameras"]

CELL_M = 1e-3
HALF = 0.15
WALL_TOP = 0.2
# name, linear RGB reflectance
REGIONS = (("red", (0.6, 0.1, 0.08)), ("green", (0.15, 0.45, 0.12)), ("blue", (0.1, 0.15, 0.55)),
           ("wall", (0.7, 0.7, 0.65)))
_DISC = (np.array([0.06, 0.0, 0.04]), 0.05)
_ENV = Path(__file__).resolve().parents[2] / "scenes" / "default" / "env.exr"


def _snap(x: np.ndarray) -> np.ndarray:
    """The centre of the grid square holding ``x`` (metres)."""
    return (np.floor(x / CELL_M) + 0.5) * CELL_M


def region_of(points: np.ndarray) -> np.ndarray:
    """True region (1-based index into :data:`REGIONS`) of points on the background.

    Parameters
    ----------
    points : (N, 3) array
        World points on the floor or the wall, metres.

    Returns
    -------
    (N,) int
        1 red, 2 green, 3 blue, 4 wall; the region of the grid square the point lies in.
    """
    p = np.asarray(points, dtype=np.float64)
    wall = np.abs(p[:, 2] + HALF) < np.abs(p[:, 1])  # nearer the wall's plane than the floor's
    x, y, z = _snap(p[:, 0]), _snap(p[:, 1]), _snap(p[:, 2])
    disc = (x - _DISC[0][0]) ** 2 + (z - _DISC[0][2]) ** 2 < _DISC[1] ** 2
    out = np.where(x < -0.03, 1, np.where(disc, 3, 2))
    return np.where(wall, 4, out)


def _grid(u: np.ndarray, v: np.ndarray, to3d) -> trimesh.Trimesh:
    """A grid of squares with corners at ``u x v`` (metres), mapped to 3-D by ``to3d(U, V)``."""
    U, V = np.meshgrid(u, v, indexing="ij")
    vertices = to3d(U.ravel(), V.ravel())
    nu, nv = len(u), len(v)
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + nv + 1, a + 1
    faces = np.concatenate([np.column_stack([a, d, c]), np.column_stack([a, c, b])])
    return trimesh.Trimesh(vertices, faces, process=False)


def _floor(n: int) -> trimesh.Trimesh:
    s = np.linspace(-HALF, HALF, n + 1)
    return _grid(s, s, lambda x, z: np.column_stack([x, np.zeros_like(x), z]))


def _wall(n: int) -> trimesh.Trimesh:
    x = np.linspace(-HALF, HALF, n + 1)
    y = np.linspace(0.0, WALL_TOP, max(2, round(n * WALL_TOP / (2 * HALF))) + 1)
    return _grid(x, y, lambda x, y: np.column_stack([x, y, np.full_like(x, -HALF)]))


def _facing(mesh: trimesh.Trimesh, towards: np.ndarray) -> trimesh.Trimesh:
    """Faces wound so their normals point along ``towards`` (diffuse surfaces in Mitsuba are
    one-sided)."""
    if np.mean(mesh.face_normals @ towards) < 0:
        mesh.faces = mesh.faces[:, ::-1]
    return mesh


def truth_scene(folder: str | Path, spp: int = 16) -> Path:
    """Write the region meshes (``region_<name>.ply``) and ``scene.toml`` into ``folder``.

    Returns
    -------
    Path
        The scene file.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cells = round(2 * HALF / CELL_M)
    parts = {"floor": _facing(_floor(cells), np.array([0.0, 1.0, 0.0])),
             "wall": _facing(_wall(cells), np.array([0.0, 0.0, 1.0]))}
    lines = ["# micropolygon-labelling truth (abs.reassembly.label_truth)", "[render]",
             f"spp = {spp}", "max_depth = 4", "", "[environment]", f'file = "{_ENV.as_posix()}"', ""]
    for name, rgb in REGIONS:
        lines += [f"[materials.{name}]", 'type = "diffuse"', f"reflectance = {list(rgb)}", ""]
    for mesh in parts.values():
        regions = region_of(mesh.triangles_center)
        for k, (name, _) in enumerate(REGIONS, start=1):
            faces = np.flatnonzero(regions == k)
            if len(faces) == 0:
                continue
            path = folder / f"region_{name}.ply"  # each region lies on one surface
            mesh.submesh([faces], append=True).export(path)
            lines += ["[[objects]]", f'name = "{name}_part"', f'mesh = "{path.name}"',
                      f'material = "{name}"', ""]
    scene = folder / "scene.toml"
    scene.write_text("\n".join(lines), encoding="utf-8")
    return scene


def scanned_background(cells: int = 3) -> trimesh.Trimesh:
    """The background as a scanner would give it: the same floor and wall, coarse and unlabelled
    (``cells`` squares across the floor), one mesh, metres, world frame."""
    return trimesh.util.concatenate([_floor(cells), _wall(cells)])


def truth_cameras(width: int, height: int, fov_deg: float = 45.0
                  ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Three cameras looking at the background from the front, left and right: ``(K, R, t)``."""
    K = intrinsics_from_fov(width, height, np.radians(fov_deg))
    target = np.array([0.0, 0.04, -0.03])
    eyes = (np.array([0.0, 0.28, 0.38]), np.array([0.22, 0.24, 0.32]), np.array([-0.24, 0.26, 0.3]))
    return [(K, *look_at(eye, target)) for eye in eyes]
