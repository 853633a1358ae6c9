"""Write a placed object into a scene file: its mesh and its ``to_world`` (scene format:
``[[objects]]`` ``mesh``, ``material``, ``to_world`` a 4x4 row-major matrix in metres; ``pose``
reset to zeros, see docs/scene-format.md)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from abs.errors import InputError
from abs.scene import load_scene, write_scene
from abs.scene.scene import ObjectSpec

__all__ = ["place_object_in_scene"]


def place_object_in_scene(scene_path: str | Path, out: str | Path, name: str, to_world: np.ndarray,
                          mesh: str | Path | None = None, material: str | None = None) -> Path:
    """Write ``out``: the scene of ``scene_path`` with object ``name`` placed by ``to_world``.

    Parameters
    ----------
    scene_path, out : path
        The scene file read, the scene file written (asset paths re-rooted).
    name : str
        The object. An existing object keeps its material unless ``material`` is given; a new
        one needs ``mesh`` and ``material``.
    to_world : (4, 4) array
        Object-to-world matrix, metres.
    mesh : path, optional
        The object's mesh (metres, object frame), e.g. the CT glass mesh ``glass.ply``.
    material : str, optional
        A material of the scene.

    Raises
    ------
    InputError
        A new object without mesh or material, or an unknown material.
    """
    scene = load_scene(scene_path)
    matrix = np.asarray(to_world, dtype=np.float64)
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        raise InputError(None, "to_world", f"expected a finite 4x4 matrix, got shape {list(matrix.shape)}")
    if material is not None and material not in scene.materials:
        raise InputError(scene_path, f"materials.{material}",
                         f"no such material; the scene has {', '.join(sorted(scene.materials))}")
    mesh_path = None if mesh is None else Path(mesh).resolve()
    if mesh_path is not None and not mesh_path.is_file():
        raise InputError(mesh_path, "", "mesh not found")
    objects = list(scene.objects)
    names = [o.name for o in objects]
    if name in names:
        i = names.index(name)
        obj = objects[i]
        objects[i] = replace(obj, mesh=mesh_path or obj.mesh, material=material or obj.material,
                             to_world=matrix, pose=np.zeros(6))
    else:
        if mesh_path is None or material is None:
            raise InputError(scene_path, "objects", f"no object {name!r} in the scene; a new object "
                                                    "needs a mesh and a material")
        objects.append(ObjectSpec(name, mesh_path, material, matrix))
    return write_scene(replace(scene, objects=tuple(objects)), out)
