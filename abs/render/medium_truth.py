"""Real subsurface scattering, rendered independently of abs's model of it.

abs models subsurface light transport in a diffuse material by a Gaussian spread of the exit point
(``subsurface``, :meth:`abs.render.integrator.PathTracer._spread`). Benchmarks must not make their
"photographs" with the model being fitted, so this module renders the truth differently: the
object (a flat cloth) becomes a slab of homogeneous, isotropically scattering medium with an
index-matched boundary, rendered by Mitsuba's volumetric path tracer ``volpath`` with Mitsuba's own
camera and environment emitter. The slab's single-scattering albedo is chosen so that, for a thick
slab, its diffuse reflectance equals the material's reflectance (Jensen et al. 2001's diffusion
approximation, inverted per channel); light spreads over the diffusion length
``mean_free_path / sqrt(3 (1 - albedo))``.

Limits: the object must be flat (a plane of constant y, facing +y, like the default tablecloth)
and its reflectance a constant RGB; glass with per-channel IORs is rendered with the red IOR
(Mitsuba's integrators have no channel passes); cameras need square pixels, no skew and the
principal point at the image centre.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

__all__ = ["render_with_medium", "albedo_for_reflectance", "diffusion_length", "mitsuba_sensor"]


def _diffuse_reflectance(albedo: np.ndarray) -> np.ndarray:
    """Diffuse reflectance of a semi-infinite, index-matched medium of single-scattering albedo
    ``albedo`` (Jensen et al. 2001, eq. for R_d with A = 1)."""
    s = np.sqrt(3.0 * (1.0 - albedo))
    return albedo / 2.0 * (1.0 + np.exp(-4.0 / 3.0 * s)) * np.exp(-s)


def albedo_for_reflectance(reflectance) -> np.ndarray:
    """Single-scattering albedo (per channel) whose thick slab has diffuse ``reflectance``.

    Parameters
    ----------
    reflectance : array-like
        Diffuse reflectance in (0, 0.8] (dimensionless).
    """
    target = np.asarray(reflectance, np.float64)
    lo, hi = np.zeros_like(target), np.ones_like(target)
    for _ in range(60):  # bisection: R_d increases with the albedo
        mid = (lo + hi) / 2
        below = _diffuse_reflectance(mid) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return (lo + hi) / 2


def diffusion_length(mean_free_path: float, albedo) -> np.ndarray:
    """How far light spreads in the medium (metres): ``mean_free_path / sqrt(3 (1 - albedo))``."""
    return mean_free_path / np.sqrt(3.0 * (1.0 - np.asarray(albedo, np.float64)))


def mitsuba_sensor(camera) -> dict:
    """A stock Mitsuba ``perspective`` sensor (tent filter, RGB film) equal to an abs camera."""
    K = np.asarray(camera.K, np.float64)
    centred = np.allclose(K[:2, 2], [(camera.width - 1) / 2, (camera.height - 1) / 2], atol=1e-6)
    if camera.block != 1 or not np.isclose(K[0, 0], K[1, 1]) or K[0, 1] != 0 or not centred:
        raise ValueError("render_with_medium needs a camera with square pixels, no skew, the "
                         "principal point at the image centre and block == 1")
    R = np.asarray(camera.R, np.float64)
    eye = camera.center
    fov = np.degrees(2.0 * np.arctan(camera.height / 2.0 / K[1, 1]))
    to_world = mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=(eye + R[2]).tolist(),
                                              up=(-R[1]).tolist())
    return {"type": "perspective", "fov": float(fov), "fov_axis": "y", "to_world": to_world,
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                     "rfilter": {"type": "tent"}, "pixel_format": "rgb"}}


def render_with_medium(compiled, camera, material: str, mean_free_path: float,
                       thickness: float | None = None, spp: int = 256, seed: int = 0,
                       max_depth: int = 256) -> np.ndarray:
    """Render ``camera``'s view with every object of ``material`` replaced by a scattering slab.

    Parameters
    ----------
    compiled : CompiledScene
        The scene (its other materials, environment and current parameter values are used).
    camera : Camera
        The view (see the module's limits).
    material : str
        A ``diffuse`` material with a constant reflectance, e.g. ``"cloth"``.
    mean_free_path : float
        1 / extinction coefficient of the medium, metres.
    thickness : float, optional
        Slab thickness in metres (default: 30 mean free paths; a black backing lies beneath).
    spp, seed, max_depth : int
        Samples per pixel, seed, and the longest path (scattering events count).

    Returns
    -------
    ndarray, shape (height, width, 3)
        Linear RGB radiance (no ``[sensor]`` applied).
    """
    mat = compiled.scene.materials[material]
    if mat.type_name != "diffuse" or mat.texture is not None:
        raise ValueError(f"{material}: render_with_medium needs a diffuse material with a constant "
                         "RGB reflectance")
    albedo = albedo_for_reflectance(compiled.get(f"{material}.reflectance"))
    thickness = 30.0 * mean_free_path if thickness is None else thickness
    d = compiled.mitsuba_dict()
    d["integrator"] = {"type": "volpath", "max_depth": int(max_depth)}
    d["sensor"] = mitsuba_sensor(camera)
    shapes = {shape.id(): shape for shape in compiled.mitsuba_scene.shapes()}
    for obj in compiled.scene.objects:
        if obj.material != material:
            continue
        sid = compiled.shape_ids[obj.name]  # the object's name unless a material shares it
        box = shapes[sid].bbox()
        lo, hi = np.array(box.min, float).ravel(), np.array(box.max, float).ravel()
        if hi[1] - lo[1] > 1e-6:
            raise ValueError(f"{obj.name}: render_with_medium needs a flat object in a plane y = const")
        top = lo[1]
        centre = [(lo[0] + hi[0]) / 2, top - thickness / 2, (lo[2] + hi[2]) / 2]
        half = [(hi[0] - lo[0]) / 2, thickness / 2, (hi[2] - lo[2]) / 2]
        del d[sid]
        d[obj.name + "_slab"] = {
            "type": "cube", "to_world": mi.ScalarTransform4f().translate(centre).scale(half),
            "bsdf": {"type": "null"},
            "interior": {"type": "homogeneous", "sigma_t": 1.0 / mean_free_path,
                         "albedo": {"type": "rgb", "value": albedo.tolist()},
                         "phase": {"type": "isotropic"}},
        }
        d[obj.name + "_backing"] = {
            "type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.0},
            "to_world": mi.ScalarTransform4f().translate([centre[0], top - thickness * 1.001, centre[2]])
            .rotate([1, 0, 0], -90).scale([half[0], half[2], 1.0]),
        }
    image = mi.render(mi.load_dict(d, optimize=False), spp=spp, seed=seed)
    return np.array(image, np.float32)[..., :3]
