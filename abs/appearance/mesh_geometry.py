"""Geometry maps (material ids and θ) of an abs scene file's objects, by ray casting its meshes.

The design's spheres have analytic geometry (:mod:`abs.appearance.geometry`); a scene file's
objects are meshes. Here every pixel's camera ray (centre and the four corners of the ±1-pixel
filter footprint, as there) is intersected with the compiled scene, and the object is told by
comparing the hit shape with each object's own shape, looked up by its Mitsuba id
(:attr:`abs.render.CompiledScene.shape_ids`) — never by ``shape_index``, whose order is not an
object's identity. θ comes from the mesh's geometric (face) normal, so it is the same whatever
shading normals a renderer interpolates. A pixel is an object's only if all five rays hit that
object first; the others get id 0.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.appearance.geometry import Geometry
from abs.errors import InputError
from abs.render.camera import Camera
from abs.render.compiled import CompiledScene

__all__ = ["mesh_scene_geometry"]


def mesh_scene_geometry(compiled: CompiledScene, camera: Camera, classes: dict[str, str]) -> Geometry:
    """θ, ids and normals of the objects named in ``classes`` (object name -> material class).

    Objects not named are background (id 0). Id ``i`` is the ``i``-th named object.
    """
    shapes = {shape.id(): shape for shape in compiled.mitsuba_scene.shapes()}
    for name in classes:
        if name not in compiled.shape_ids:
            raise InputError(None, "--class", f"no object {name!r} in the scene; it has "
                                              f"{sorted(compiled.shape_ids)}")
    targets = [shapes[compiled.shape_ids[name]] for name in classes]
    w, h = camera.width, camera.height
    index = dr.arange(mi.UInt32, w * h)
    u, v = mi.Float(index % w), mi.Float(index // w)

    def cast(du: float, dv: float):
        origin, d = camera.rays(u + du, v + dv)
        si = compiled.mitsuba_scene.ray_intersect(mi.Ray3f(origin, d))
        ids = np.zeros(w * h, np.int32)
        for i, shape in enumerate(targets):
            hit = si.is_valid() & (si.shape == mi.ShapePtr(shape))
            ids[np.asarray(hit, bool)] = i + 1
        return ids, si, d

    ids, si, d = cast(0.0, 0.0)
    pure = ids > 0
    for du, dv in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        pure &= cast(float(du), float(dv))[0] == ids
    normals = np.stack([np.asarray(c, np.float64) for c in (si.n.x, si.n.y, si.n.z)], axis=1)
    dirs = np.stack([np.asarray(c, np.float64) for c in (d.x, d.y, d.z)], axis=1)
    facing = -np.einsum("ij,ij->i", normals, dirs)
    normals = np.where(facing[:, None] < 0, -normals, normals)  # the side the camera sees
    theta = np.where(pure, np.arccos(np.clip(np.abs(facing), 0.0, 1.0)), np.nan)
    ids = np.where(pure, ids, 0)
    normals = np.where(pure[:, None], normals, 0.0)
    return Geometry(theta.reshape(h, w).astype(np.float32), ids.reshape(h, w).astype(np.int32),
                    tuple(classes.values()), normals.reshape(h, w, 3).astype(np.float32))
