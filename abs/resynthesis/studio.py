"""The fitted scene as files abs reads: scene file, mesh, environment map and a one-view capture.

The edit is an ordinary abs fit (:func:`abs.fit`) of a scene file to a capture folder, so the
photograph's scene is written as one: a camera at the origin looking along world +z with +y up
(the frame of the baseline's environment map, :mod:`abs.editing.environment`), the inflated mesh
(:mod:`~abs.resynthesis.inflation`) and the environment with its backdrop
(:mod:`~abs.resynthesis.backdrop`). Storage only: no decisions are made here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import tomli_w

from abs.camera.pinhole import intrinsics_from_fov, look_at

__all__ = ["photo_camera", "write_mesh", "write_environment", "write_scene_file", "write_capture"]

MESH_FILE = "object.ply"
ENVIRONMENT_FILE = "environment.exr"


def photo_camera(shape: tuple[int, int], fov_deg: float) -> dict:
    """The photograph's pinhole camera as a capture view (``name``, ``K``, ``R``, ``t``).

    Parameters
    ----------
    shape : tuple of int
        ``(height, width)`` pixels.
    fov_deg : float
        Vertical field of view, degrees.
    """
    h, w = shape
    R, t = look_at(np.zeros(3), np.array([0.0, 0.0, 1.0]))
    return {"name": "photo", "K": intrinsics_from_fov(w, h, np.deg2rad(fov_deg)), "R": R, "t": t,
            "holdout": False}


def write_mesh(folder: Path, vertices_cam: np.ndarray, faces: np.ndarray, R: np.ndarray,
               t: np.ndarray) -> Path:
    """Write the mesh (camera-frame vertices, metres) in world coordinates as PLY."""
    import trimesh

    world = (vertices_cam - t) @ R  # x_cam = R X + t  =>  X = R^T (x_cam - t)
    path = Path(folder) / MESH_FILE
    trimesh.Trimesh(world, faces, process=False).export(path)
    return path


def write_environment(folder: Path, environment: np.ndarray) -> Path:
    """Write the lat-long map that the scene files name."""
    from abs.io.images import write_exr

    path = Path(folder) / ENVIRONMENT_FILE
    write_exr(path, environment)
    return path


def write_scene_file(folder: Path, name: str, material: dict, spp: int, max_depth: int,
                     scale: float = 1.0) -> Path:
    """Write ``name`` (a scene file) with one object ``object`` of material ``material``, lit by
    the map of :func:`write_environment`."""
    folder = Path(folder)
    table = {"render": {"spp": int(spp), "max_depth": int(max_depth)},
             "environment": {"file": ENVIRONMENT_FILE, "scale": float(scale)},
             "materials": {"material": material},
             "objects": [{"name": "object", "mesh": MESH_FILE, "material": "material"}]}
    path = folder / name
    path.write_text(tomli_w.dumps(table), encoding="utf-8")
    return path


def write_capture(folder: Path, view: dict, photo: np.ndarray, mask: np.ndarray):
    """A one-view capture (the photograph, compared on the object's mask)."""
    from abs.io.capture import save_capture

    return save_capture(folder, [view], {view["name"]: photo}, {view["name"]: mask})
