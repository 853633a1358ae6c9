"""Design scenes as Mitsuba scene dictionaries, with abs's material types and camera.

Built from Mitsuba's analytic shapes (``rectangle`` walls, ``sphere`` objects) rather than a scene
file of meshes: the geometry maps (:mod:`abs.appearance.geometry`) need the exact spheres, and a
tessellated sphere would make the renderer's normals differ from them. The materials go through
abs's own material types (:mod:`abs.scene.materials`), so a sample means here what it means in a
scene file; a ``merl`` sample's table is made once from the shared neural fits and cached.
"""

from __future__ import annotations

from pathlib import Path

import mitsuba as mi
import numpy as np

from abs.appearance.design import SceneSpec, sphere_array
from abs.appearance.geometry import Geometry, sphere_geometry
from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render.camera import Camera
from abs.scene.fields import Fields
from abs.scene.materials.base import material_class

__all__ = ["design_camera", "scene_dict", "scene_geometry", "material_bsdf", "merl_file"]

EYE = (0.0, 0.42, 1.55)
TARGET = (0.0, 0.3, 0.0)
FOV_DEG = 34.0


def design_camera(size: int) -> Camera:
    """The square view of every design scene, ``size`` pixels a side (34° field of view)."""
    R, t = look_at(np.array(EYE), np.array(TARGET))
    return Camera(intrinsics_from_fov(size, size, np.radians(FOV_DEG)), R, t, size, size)


def scene_geometry(spec: SceneSpec, camera: Camera) -> Geometry:
    """θ and material ids of ``spec`` seen by ``camera`` (see :mod:`abs.appearance.geometry`)."""
    return sphere_geometry(camera.K, camera.R, camera.t, camera.width, camera.height,
                           sphere_array(spec), tuple(s.material_class for s in spec.spheres))


def merl_file(name: str) -> Path:
    """A MERL ``.binary`` table of the shared neural fit ``name``, written once to the cache."""
    from abs.brdf.nbrdf import nbrdf_table
    from abs.io.merl import write_merl
    from abs.io.shared_data import cache_dir

    path = cache_dir("appearance") / f"{name}.binary"
    if not path.is_file():
        tmp = path.with_suffix(".tmp")
        write_merl(tmp, nbrdf_table(name))
        tmp.replace(path)  # a concurrent reader never sees half a table
    return path


def material_bsdf(table: dict, name: str) -> dict:
    """The Mitsuba BSDF of an abs material given as a scene-file table (``type`` and fields).

    A ``merl`` table names a shared fit (``name``) instead of a file.
    """
    table = dict(table)
    if table["type"] == "merl":
        table = {"type": "merl", "file": str(merl_file(table.pop("name")))}
    cls = material_class(table["type"])
    material = cls.from_fields(name, Fields(table, Path("<appearance design>"), f"materials.{name}"))
    return material.to_mitsuba()


def _diffuse(rgb) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(map(float, rgb))}}


def _rectangle(to_world: mi.ScalarTransform4f, rgb) -> dict:
    return {"type": "rectangle", "to_world": to_world, "bsdf": _diffuse(rgb)}


def scene_dict(spec: SceneSpec) -> dict:
    """Mitsuba dictionary of ``spec``: a 1 m box (floor y = 0, back wall z = -0.5, side walls
    x = ±0.5, open at the front and the top) and the spheres. No emitter: abs's renderer lights
    it with an environment, stock Mitsuba needs one added (:mod:`abs.appearance.renderers`)."""
    T = mi.ScalarTransform4f
    d = {"type": "scene"}
    if spec.box:
        d |= {"floor": _rectangle(T().rotate([1, 0, 0], -90).scale(0.5), spec.floor),
              "back": _rectangle(T().translate([0, 0.5, -0.5]).scale(0.5), spec.walls),
              "left": _rectangle(T().translate([-0.5, 0.5, 0]).rotate([0, 1, 0], 90).scale(0.5), spec.walls),
              "right": _rectangle(T().translate([0.5, 0.5, 0]).rotate([0, 1, 0], -90).scale(0.5),
                                  spec.walls)}
    for i, sphere in enumerate(spec.spheres):
        name = f"object{i + 1}"
        d[name] = {"type": "sphere", "center": list(sphere.centre), "radius": sphere.radius,
                   "bsdf": {**material_bsdf(sphere.material, name), "id": f"{name}_bsdf"}}
    return d
