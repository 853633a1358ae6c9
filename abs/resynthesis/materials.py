"""Scene-file materials of the analysis-by-synthesis edit: the current one and the targets.

The current material is ``plastic`` (a diffuse base under a GGX-rough coating): its reflectance
is fitted, its roughness chosen among candidates by a sun's highlight where there is one
(:mod:`~abs.resynthesis.highlight`), else by the fit residual (:mod:`~abs.resynthesis.method`).
A target is made from the fitted current material where the spec leaves a quantity open:

============================  ====================================================================
spec                          target material (scene-file table)
============================  ====================================================================
``glossier``                  the fitted plastic, roughness / :data:`GLOSSIER_FACTOR`
``diffuse``                   the fitted plastic, roughness x :data:`DIFFUSE_FACTOR` (at most 1)
``merl:NAME``                 the measured table NAME (``merl``)
``glass:clear``               smooth ``dielectric``, IOR :data:`GLASS_IOR`
``glass:frosted``             ``dielectric`` of Beckmann roughness :data:`FROSTED_ROUGHNESS`
``glass:tinted``              ``dielectric`` absorbing so that the transmittance across the
                              object's diameter is the fitted reflectance over its largest channel
                              (the object's own colour becomes the glass's tint)
``glass:dark``                ``dielectric`` transmitting :data:`DARK_TRANSMITTANCE` across the
                              diameter in every channel
``translucent``               ``dielectric`` of roughness :data:`TRANSLUCENT_ROUGHNESS`: a
                              stand-in (no subsurface scattering in abs's renderer)
============================  ====================================================================

The factors are abs's choices (the specs name a direction, not an amount); benchmarks/
material_edit.py makes its truths with the same amounts, so it scores the rendering of the
edit, not the guess of how much glossier "glossier" means.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from abs.editing.spec import MaterialSpec
from abs.errors import InputError

__all__ = ["GLOSSIER_FACTOR", "DIFFUSE_FACTOR", "GLASS_IOR", "FROSTED_ROUGHNESS",
           "TRANSLUCENT_ROUGHNESS", "DARK_TRANSMITTANCE", "current_material", "target_material",
           "check_target", "KEEPS_SURFACE"]

GLOSSIER_FACTOR = 5.0
"""``glossier`` divides the roughness by this."""
DIFFUSE_FACTOR = 4.0
"""``diffuse`` multiplies the roughness by this."""
GLASS_IOR = 1.5
FROSTED_ROUGHNESS = 0.15
TRANSLUCENT_ROUGHNESS = 0.6
DARK_TRANSMITTANCE = 0.1
KEEPS_SURFACE = ("glossier", "diffuse")
"""Kinds that keep the surface (its pigment and coating; only the roughness changes): the
photograph's residual against the fitted current material belongs to that surface and stays in
the edit (differential rendering, ``method.composite``). Every other kind replaces the surface,
and its rendering replaces the object."""


def current_material(reflectance, roughness: float) -> dict:
    """The scene-file table of the current material (plastic)."""
    return {"type": "plastic", "reflectance": [float(v) for v in np.asarray(reflectance)],
            "roughness": float(roughness)}


def check_target(spec: MaterialSpec) -> None:
    """Refuse a target this method cannot render (before any fit is spent on it).

    Raises
    ------
    InputError
        For ``texture:FILE``: the inflated mesh has no UV parametrisation yet.
    """
    if spec.kind == "texture":
        raise InputError(None, "to", "the synthesis method does not re-texture yet (no UV "
                                     "parametrisation of the inflated mesh); use --method baseline")


def target_material(spec: MaterialSpec, reflectance, roughness: float, diameter_m: float,
                    folder: Path, merl_dir: str | None = None) -> dict:
    """The scene-file table of the edit's target (module docstring).

    Parameters
    ----------
    spec : MaterialSpec
        The target.
    reflectance : array_like, shape (3,)
        The fitted reflectance of the current material.
    roughness : float
        Its roughness (GGX alpha).
    diameter_m : float
        The object's largest extent, metres (sets absorption per metre from a transmittance).
    folder : Path
        Where a MERL table is written for the scene file to name.
    merl_dir : str, optional
        Folder of real MERL ``.binary`` files (default: the shared neural fits).

    Raises
    ------
    InputError
        For a texture edit (not built for this method) or an unknown MERL material.
    """
    rho = np.clip(np.asarray(reflectance, np.float64), 1e-4, 1.0)
    if spec.kind in ("glossier", "diffuse"):
        r = (roughness / GLOSSIER_FACTOR if spec.kind == "glossier"
             else min(roughness * DIFFUSE_FACTOR, 1.0))
        return current_material(rho, r)
    if spec.kind == "merl":
        from abs.brdf.measured import measured_material_names, measured_table
        from abs.io.merl import write_merl

        names = measured_material_names(merl_dir)
        if spec.argument not in names:
            raise InputError(merl_dir, "to", f"unknown MERL material {spec.argument!r}; known: "
                                             f"{', '.join(names)}")
        path = Path(folder) / f"{spec.argument}.binary"
        write_merl(path, np.maximum(measured_table(spec.argument, merl_dir), 0.0))
        return {"type": "merl", "file": path.name}
    check_target(spec)
    glass = {"type": "dielectric", "ior": [GLASS_IOR] * 3}
    variant = spec.argument if spec.kind == "glass" else "translucent"
    if variant == "frosted":
        glass["roughness"] = FROSTED_ROUGHNESS
    elif variant == "translucent":
        glass["roughness"] = TRANSLUCENT_ROUGHNESS
    elif variant == "tinted":
        glass["absorption"] = (-np.log(rho / rho.max()) / diameter_m).tolist()
    elif variant == "dark":
        glass["absorption"] = [float(-np.log(DARK_TRANSMITTANCE) / diameter_m)] * 3
    return glass
