"""Material editing by analysis by synthesis (issue 30, "Beyond the paper").

The baseline's estimates (:func:`abs.editing.edit.estimate`) are the starting point; abs's
renderer then explains the photograph, and the edit is a rendering:

1. **Scene.** A pinhole camera of the photograph's field of view (``fov_deg``: one photograph
   does not give it) at the origin; the object as the mask inflated into a closed round solid
   (:mod:`~abs.resynthesis.inflation`); the environment as the baseline's map with the
   photograph's filled background painted in where the camera sees it
   (:mod:`~abs.resynthesis.backdrop`).
2. **Fit** (:func:`abs.fit`, Levenberg-Marquardt with Laplace errors): the current material's
   reflectance (``plastic``) and the environment's scale, for each candidate roughness; the
   candidate with the smallest residual wins. The residual RMSE against the photograph, and its
   ratio to the pixel noise, is the edit's trust measure (``EditResult.trust``).
3. **Scene of the edit.** The fitted scale is applied to the part of the map the camera did not
   see; the backdrop keeps the photograph's own radiance (scale 1), so what glass shows of it
   matches the photograph around the object.
4. **Render** the object with the target material (:mod:`~abs.resynthesis.materials`) and with
   the fitted current one, same seed.
5. **Composite** with the mask. Opaque targets (gloss, measured BRDF): differential rendering
   (Debevec 1998), ``photo + (new - current)``: what the fitted model misses of the photograph
   (its residual) stays in the edit, and the edit of the current material to itself is the
   photograph up to Monte-Carlo noise. Glass and translucency: the rendering itself, because the
   residual of an opaque fit describes a surface that is no longer there.

Not (yet) refined: the shape (the inflation is kept as it is, ``relief`` 1) and the environment
beyond one scale (the unseen half of the map stays the baseline's mirror image).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abs.colour.srgb import luminance
from abs.editing.edit import EditResult, EditSettings, Estimates
from abs.editing.spec import MaterialSpec
from abs.errors import InputError
from abs.resynthesis.backdrop import environment_with_backdrop
from abs.resynthesis.inflation import inflated_mesh
from abs.resynthesis.materials import TRANSMISSIVE, current_material, target_material
from abs.resynthesis.studio import (photo_camera, write_capture, write_environment, write_mesh,
                                    write_scene_file)

__all__ = ["SynthesisSettings", "synthesis_edit", "composite"]


@dataclass(frozen=True)
class SynthesisSettings:
    """Settings of the analysis-by-synthesis edit.

    Attributes
    ----------
    fov_deg : float
        The photograph's vertical field of view, degrees (a pinhole camera).
    distance_m : float
        Distance of the silhouette's plane from the camera, metres. Images are scale-free
        (an object twice as large twice as far looks the same) except through absorption, which
        :mod:`~abs.resynthesis.materials` sets per object diameter, so this only sets units.
    relief : float
        Depth of the inflated mesh relative to a round solid (1: a sphere for a disc).
    roughness_candidates : tuple of float
        GGX roughness of the current plastic tried; the smallest residual wins.
    map_height : int
        Height of the environment map (width twice); the field of view must get about a texel per
        pixel for the backdrop seen through glass to stay sharp.
    fit_spp, render_spp : int
        Samples per pixel of the fit's renders and of the final renders.
    max_iterations, refinement_steps : int
        The fit's Levenberg-Marquardt evaluations and Gauss-Newton refinement steps.
    max_depth : int
        Path segments (glass needs several).
    seed : int
        Seed of the renders.
    folder : str or None
        Where the scene, capture and fits are written; ``None``: a temporary folder, removed.
    """

    fov_deg: float = 24.0
    distance_m: float = 1.0
    relief: float = 1.0
    roughness_candidates: tuple[float, ...] = (0.05, 0.1, 0.2)
    map_height: int = 1024
    fit_spp: int = 8
    render_spp: int = 64
    max_iterations: int = 8
    refinement_steps: int = 2
    max_depth: int = 12
    seed: int = 0
    folder: str | None = None


def _initial_reflectance(rgb: np.ndarray, mask: np.ndarray, environment: np.ndarray) -> np.ndarray:
    # A Lambertian surface under a uniform environment of radiance E reflects rho E: the ratio of
    # the object's mean colour to the map's mean radiance (per channel) starts the fit inside
    # the bounds and near the scale the environment asks for.
    ratio = rgb[mask].mean(axis=0) / np.maximum(environment.reshape(-1, 3).mean(axis=0), 1e-9)
    return np.clip(ratio, 0.02, 0.95)


def composite(photo: np.ndarray, mask: np.ndarray, new: np.ndarray, current: np.ndarray,
              differential: bool) -> np.ndarray:
    """The edited photograph: inside ``mask`` the rendering of the target, outside the photograph.

    Parameters
    ----------
    photo, new, current : np.ndarray
        ``(height, width, 3)`` linear: the photograph, the target's and the fitted current
        material's renderings (same camera and seed).
    mask : np.ndarray
        ``(height, width)`` bool, the object's matte.
    differential : bool
        ``photo + new - current`` inside the mask (module docstring, step 5) instead of ``new``.
    """
    inside = photo + new - current if differential else new
    return np.where(mask[..., None], np.maximum(inside, 0.0), photo).astype(np.float32)


def _fit_current(folder: Path, syn: SynthesisSettings, reflectance0: np.ndarray) -> dict:
    """Fit reflectance and environment scale for each candidate roughness; the best fit."""
    from abs.fitting import FitSettings, fit

    settings = FitSettings(spp=syn.fit_spp, max_iterations=syn.max_iterations,
                           refinement_steps=syn.refinement_steps, seed=syn.seed,
                           eval_spp=syn.fit_spp)
    fits = {}
    for roughness in syn.roughness_candidates:
        scene = write_scene_file(folder, f"fit_{roughness:g}.toml",
                                 current_material(reflectance0, roughness), syn.fit_spp,
                                 syn.max_depth)
        result = fit(scene, folder / "capture", ["material.reflectance", "environment.scale"],
                     settings)
        fits[roughness] = result
    best = min(fits, key=lambda r: fits[r].metrics["train_rmse"]["after"])
    result = fits[best]
    stderr = result.vector.split(result.uncertainty.stderr)
    return {"roughness": best,
            "reflectance": result.values["material.reflectance"].tolist(),
            "reflectance_stderr": stderr["material.reflectance"].tolist(),
            "scale": float(result.values["environment.scale"][0]),
            "scale_stderr": float(stderr["environment.scale"][0]),
            "residual_rmse": result.metrics["train_rmse"]["after"],
            "initial_rmse": result.metrics["train_rmse"]["before"],
            "noise": result.image_noise,
            "candidates": {f"{r:g}": fits[r].metrics["train_rmse"]["after"] for r in fits},
            "checks": list(result.checks)}


def synthesis_edit(rgb: np.ndarray, mask: np.ndarray, spec: MaterialSpec, settings: EditSettings,
                   est: Estimates, texture: np.ndarray | None = None) -> EditResult:
    """The ``synthesis`` method of :func:`abs.editing.edit` (module docstring).

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` the checked linear HDR photograph.
    mask : np.ndarray
        ``(height, width)`` bool, the checked matte.
    spec : MaterialSpec
        The target.
    settings : EditSettings
        ``settings.synthesis`` (a :class:`SynthesisSettings`, or ``None`` for the defaults).
    est : Estimates
        The baseline's estimates (background, environment, depth ...).
    texture : np.ndarray, optional
        Unused (re-texturing is refused by this method).

    Returns
    -------
    EditResult
        With ``trust``: the fit (residual RMSE, noise, their ratio, the residual relative to the
        object's mean radiance, fitted values with standard errors, the candidates' residuals).
    """
    syn = settings.synthesis or SynthesisSettings()
    if not isinstance(syn, SynthesisSettings):
        raise InputError(None, "settings.synthesis", f"expected SynthesisSettings, got "
                                                     f"{type(syn).__name__}")
    if spec.kind == "texture":
        target_material(spec, np.ones(3), 0.1, 1.0, Path("."))  # raises the method's refusal
    from abs.render import Camera
    from abs.render import compile_scene
    from abs.scene import load_scene

    h, w = mask.shape
    view = photo_camera((h, w), syn.fov_deg)
    vertices, faces = inflated_mesh(mask, view["K"], syn.distance_m, syn.relief)
    diameter = float(np.ptp(vertices, axis=0).max())
    environment, seen = environment_with_backdrop(est.environment, est.background, view["K"],
                                                  syn.map_height)
    with tempfile.TemporaryDirectory(prefix="abs-edit-") as tmp:
        folder = Path(syn.folder) if syn.folder else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        write_mesh(folder, vertices, faces, view["R"], view["t"])
        write_capture(folder / "capture", view, rgb, mask)
        write_environment(folder, environment)
        trust = _fit_current(folder, syn, _initial_reflectance(rgb, mask, environment))
        # The unseen part of the map carries the fitted scale; the backdrop is measured radiance.
        fitted_env = np.where(seen[..., None], environment, environment * trust["scale"])
        camera = Camera(view["K"], view["R"], view["t"], w, h)
        write_environment(folder, fitted_env)
        renders = {}
        for name, material in (("current", current_material(trust["reflectance"], trust["roughness"])),
                               ("new", target_material(spec, trust["reflectance"], trust["roughness"],
                                                       diameter, folder, settings.merl_dir))):
            path = write_scene_file(folder, f"{name}.toml", material, syn.render_spp, syn.max_depth)
            renders[name] = np.asarray(compile_scene(load_scene(path)).render(
                camera, syn.render_spp, seed=syn.seed + 7).numpy(), np.float32)
    image = composite(rgb, mask, renders["new"], renders["current"],
                      differential=spec.kind not in TRANSMISSIVE)
    level = float(np.mean(luminance(rgb)[mask]))
    trust.update(noise_ratio=trust["residual_rmse"] / max(trust["noise"], 1e-12),
                 relative_residual=trust["residual_rmse"] / max(level, 1e-12),
                 object_diameter_m=diameter, fov_deg=syn.fov_deg)
    return EditResult(image, spec, mask, est.depth, est.normals, est.background, fitted_env,
                      est.highlight_threshold, est.highlights, settings, "synthesis", trust)
