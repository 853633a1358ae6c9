"""HDR images of a sample lit by the scanner's point light, rendered with its true BRDF.

The renderer is a direct-lighting pass written on Mitsuba's ray tracing and abs's
``abs_tabulated`` BSDF (the measured table, trilinearly interpolated): each camera ray finds the
surface, a shadow ray tests the light, and the pixel records

    L = f(ωi, ωo) (ωi·n) I / d²,

the radiance of a surface point lit by a point light of intensity ``I`` at distance ``d``. For a
convex sample alone in the dark this is the exact image (there is nothing to inter-reflect).
Each pixel averages ``spp`` stratified-random positions over its area (a box filter, like a
sensor pixel). Images are linear RGB in W/(m² sr) for ``I`` in W/sr.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.bsdfs import tabulated as _tabulated  # noqa: F401  (registers abs_tabulated)
from abs.render.camera import Camera
from abs.studies.sl_rig import RigCamera, SampleMesh, ScannerRig

__all__ = ["render_point_lit", "render_scan", "sample_scene", "set_table"]

# Shadow rays leave the surface this far (metres) along the normal, far below the 1 mm noise.
SURFACE_OFFSET_M = 1e-5


def sample_scene(mesh: SampleMesh, table: np.ndarray | None = None) -> mi.Scene:
    """A Mitsuba scene holding only the sample mesh (id ``sample``) with an ``abs_tabulated`` BSDF.

    Parameters
    ----------
    mesh : SampleMesh
        Geometry in the sample's frame; its normals become the shading normals.
    table : np.ndarray, optional
        BRDF table (MERL layout, 1/sr); all zeros when omitted (e.g. a scene for ray tests only).
    """
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "abs_tabulated"})
    shape = mi.Mesh("sample", mesh.n_vertices, int(mesh.faces.shape[0]), props, has_vertex_normals=True)
    params = mi.traverse(shape)
    params["vertex_positions"] = mi.Float(mesh.vertices.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
    params["vertex_normals"] = mi.Float(mesh.normals.astype(np.float32).ravel())
    params.update()
    scene = mi.load_dict({"type": "scene", "sample": shape})
    if table is not None:
        set_table(scene, table)
    return scene


def set_table(scene: mi.Scene, table: np.ndarray) -> None:
    """Replace the sample's BRDF table (MERL layout, 1/sr, values < 0 clamped to 0)."""
    params = mi.traverse(scene)
    params["sample.bsdf.table"] = mi.Float(np.maximum(np.asarray(table, np.float32).ravel(), 0.0))
    params.update()


def _camera(cam: RigCamera) -> Camera:
    return Camera(cam.K, cam.R, cam.t, cam.width, cam.height)


def render_point_lit(scene: mi.Scene, cam: RigCamera, light_position: np.ndarray, intensity: float,
                     spp: int = 4, seed: int = 0) -> np.ndarray:
    """One HDR image of ``scene`` lit only by a point light.

    Parameters
    ----------
    cam : RigCamera
        The camera, in the scene's frame.
    light_position : np.ndarray
        (3,) light position in the scene's frame, metres.
    intensity : float
        Radiant intensity per channel, W/sr.
    spp : int
        Positions per pixel, uniform over the pixel's area.

    Returns
    -------
    np.ndarray
        float32 (height, width, 3) radiance; 0 where the ray misses the sample.
    """
    w, h = cam.width, cam.height
    n = w * h * spp
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    pixel = dr.arange(mi.UInt32, n) // spp
    offset = sampler.next_2d() - 0.5
    origin, d = _camera(cam).rays(mi.Float(pixel % w) + offset.x, mi.Float(pixel // w) + offset.y)
    si = scene.ray_intersect(mi.Ray3f(origin, d))
    light = mi.Point3f(*[float(x) for x in light_position])
    to_light = light - si.p
    dist2 = dr.squared_norm(to_light)
    wi = to_light / dr.sqrt(dist2)
    valid = si.is_valid()
    shadow_origin = si.p + si.n * SURFACE_OFFSET_M
    occluded = scene.ray_test(mi.Ray3f(shadow_origin, wi, dr.sqrt(dist2) * (1.0 - 1e-4), 0.0,
                                       mi.Color0f()), valid)
    lit = valid & ~occluded
    # abs_tabulated's eval returns f · cos θ of its second direction (Mitsuba's wo = towards the light).
    value = si.bsdf().eval(mi.BSDFContext(), si, si.to_local(wi), lit) * (float(intensity) / dist2)
    value = dr.select(lit, value, 0.0)
    channels = [dr.block_sum(c, spp) / spp for c in (value.x, value.y, value.z)]
    return np.stack([np.asarray(c, np.float32).reshape(h, w) for c in channels], axis=-1)


def render_scan(rig: ScannerRig, mesh: SampleMesh, table: np.ndarray, spp: int = 4,
                seed: int = 0) -> np.ndarray:
    """All images of a scan: every turntable step seen by every camera.

    Returns
    -------
    np.ndarray
        float32 (steps, cameras, height, width, 3) radiance.
    """
    scene = sample_scene(mesh, table)
    images = []
    for k, angle in enumerate(rig.turntable_angles):
        light = rig.light_at_step(angle)
        images.append([render_point_lit(scene, cam.at_step(angle), light, rig.light_intensity, spp,
                                        seed=seed + 1000 * k + c)
                       for c, cam in enumerate(rig.cameras)])
    return np.asarray(images, np.float32)
