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
   candidate with the smallest residual wins, unless a sun's highlight was left out: then, under
   the light of step 3, the candidate whose coating lobe, lit by a sun fitted to that highlight,
   reproduces it best (:mod:`~abs.resynthesis.highlight`; the residuals of the rest barely tell
   the roughness), and step 3 again for it if it is another. The fit compares the matte less its
   outline and less a sun's sharp highlight (:func:`fit_mask`).
3. **Light.** The unseen part of the map (the backdrop stays as photographed) replaced by a
   smooth map fitted to the object as a light probe (:mod:`~abs.resynthesis.lighting`), starting
   from the scaled baseline map; then the material and scale fitted again under it. The residual
   RMSE against the photograph, and its ratio to the pixel noise, is the edit's trust measure
   (``EditResult.trust``).
4. **Render** the object with the target material (:mod:`~abs.resynthesis.materials`) and with
   the fitted current one, same seed; the fitted scale applies to the unseen light only. A gloss
   edit's two renderings are lit by the fitted sun as well, which reshapes its highlight.
5. **Composite** with the mask. Edits that keep the surface and change its roughness
   (``glossier``, ``diffuse``): differential rendering (Debevec 1998), ``photo + (new -
   current)``: what the fitted model misses of the photograph (its residual) stays in the edit,
   and the edit of the current material to itself is the photograph up to Monte-Carlo noise.
   Edits that replace the surface (a measured BRDF, glass, translucency): the rendering itself,
   because the residual of the fit describes a surface that is no longer there (its pigment where
   the fit under-explains it, the coating's left-out highlights). On
   ``benchmarks/material_edit.py`` the measured-BRDF edit composited differentially kept the
   old plastic's colour and was 22 % better than the baseline (ΔE00 of the three scenes' means);
   rendered, 50 %.

Not refined: the shape (the inflation is kept as it is, ``relief`` 1) and the field of view.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from abs.colour.srgb import luminance
from abs.editing.edit import EditResult, EditSettings, Estimates
from abs.editing.spec import MaterialSpec
from abs.errors import InputError
from abs.resynthesis.backdrop import environment_with_backdrop, frustum_texels
from abs.resynthesis.highlight import sun_map
from abs.resynthesis.inflation import inflated_mesh
from abs.resynthesis.lighting import hat_averages, hat_basis, map_from_gains, solve_gains
from abs.resynthesis.materials import (KEEPS_SURFACE, check_target, current_material,
                                       target_material)
from abs.resynthesis.studio import (photo_camera, write_capture, write_environment, write_mesh,
                                    write_scene_file)

__all__ = ["SynthesisSettings", "FittedScene", "fit_photograph", "render_material", "edit_fitted",
           "synthesis_edit", "composite"]


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
    map_height : int or None
        Height of the environment map (width twice). ``None``: a texel per pixel of the
        photograph across the field of view (``height 180 / fov_deg``, between 256 and 2048), so
        that the backdrop seen through glass stays as sharp as photographed.
    fit_spp, render_spp : int
        Samples per pixel of the fit's renders and of the final renders.
    max_iterations, refinement_steps : int
        The fit's Levenberg-Marquardt evaluations and Gauss-Newton refinement steps.
    max_depth : int
        Path segments (glass needs several).
    light_grid : tuple of int
        ``(n_theta, n_phi)`` nodes of the smooth map fitted to the unseen light
        (:mod:`~abs.resynthesis.lighting`); ``(0, 0)``: keep the baseline's map, scaled.
    light_spp : int
        Samples per pixel of each basis rendering of that fit.
    light_ridge : float
        Its pull towards the baseline's map (:func:`~abs.resynthesis.lighting.solve_gains`).
    highlight_factor : float or None
        Highlights holding a pixel brighter than this times the object's median luminance are
        left out of the fits (:func:`fit_mask`); ``None`` keeps them.
    highlight_roughness : bool
        When such a highlight was left out, fit a sun to it, choose the roughness by how well
        that sun reproduces it (:mod:`~abs.resynthesis.highlight`), not by the residual of the
        rest, and light gloss edits with it (with one candidate roughness: only the latter).
    sun_spp : int
        Samples per pixel of that test's renderings of the current material under the fitted
        light (the sun's own are evaluated, not sampled).
    seed : int
        Seed of the renders.
    folder : str or None
        Where the scene, capture and fits are written; ``None``: a temporary folder, removed.
    """

    fov_deg: float = 24.0
    distance_m: float = 1.0
    relief: float = 1.0
    roughness_candidates: tuple[float, ...] = (0.05, 0.1, 0.2)
    map_height: int | None = None
    fit_spp: int = 8
    render_spp: int = 256
    max_iterations: int = 8
    refinement_steps: int = 2
    max_depth: int = 12
    light_grid: tuple[int, int] = (7, 8)
    light_spp: int = 16
    light_ridge: float = 1e-3
    highlight_factor: float | None = 20.0
    highlight_roughness: bool = True
    sun_spp: int = 32
    seed: int = 0
    folder: str | None = None

    def __post_init__(self):
        field = "settings.synthesis"
        if not 0 < self.fov_deg < 180:
            raise InputError(None, f"{field}.fov_deg", f"expected degrees in (0, 180), got "
                                                       f"{self.fov_deg}")
        for name in ("fit_spp", "render_spp", "light_spp", "sun_spp", "max_iterations",
                     "max_depth"):
            if getattr(self, name) < 1:
                raise InputError(None, f"{field}.{name}", f"must be at least 1, got "
                                                          f"{getattr(self, name)}")
        if not self.roughness_candidates or not all(0 <= r <= 1 for r in self.roughness_candidates):
            raise InputError(None, f"{field}.roughness_candidates", "expected one or more GGX "
                             f"roughnesses in [0, 1], got {self.roughness_candidates}")
        if self.highlight_factor is not None and not self.highlight_factor > 1:
            raise InputError(None, f"{field}.highlight_factor", f"expected a factor > 1 or None, "
                                                                f"got {self.highlight_factor}")
        if self.distance_m <= 0 or self.relief <= 0:
            raise InputError(None, field, f"distance_m and relief must be > 0, got "
                                          f"{self.distance_m} and {self.relief}")


def _initial_reflectance(rgb: np.ndarray, mask: np.ndarray, environment: np.ndarray) -> np.ndarray:
    # A Lambertian surface under a uniform environment of radiance E reflects rho E: the ratio of
    # the object's mean colour to the map's mean radiance (per channel) starts the fit inside
    # the bounds and near the scale the environment asks for.
    ratio = rgb[mask].mean(axis=0) / np.maximum(environment.reshape(-1, 3).mean(axis=0), 1e-9)
    return np.clip(ratio, 0.02, 0.95)


def fit_mask(mask: np.ndarray, rgb: np.ndarray | None = None,
             highlight_factor: float | None = None) -> np.ndarray:
    """The pixels the fit compares: the matte less its outline, and less sharp highlights.

    A pixel on the outline is a mix of object and background in the photograph, but wholly
    object in a rendering of the inflated mesh (whose outline runs along the pixels' edges), so it
    is left out unless that would leave too few (an object a few pixels wide).

    A sharp highlight is left out too: the mirror image of a small bright source (a sun), which
    the fitted light, a smooth map, cannot hold. In least squares such pixels outweigh the rest:
    on ``benchmarks/material_edit.py``'s blue ellipsoid in a sunny map, 1.5 % of the pixels, up to
    290 times the median luminance, carried a third of the light and pulled the reflectance of a
    blue plastic to (0.64, 0.02, 0.01). A highlight is a connected region brighter than a quarter
    of ``highlight_factor`` times the median luminance of the inner pixels that holds a pixel
    brighter than ``highlight_factor`` times it (hysteresis, as Canny's edges): a sun's
    reflection goes with its bright wings, while the broad reflections of a sky (at most 8-12
    times the median on the benchmark's sunless maps) stay in the fit, which needs them: the
    coating's reflection, of known strength, is what tells the light's level from the surface's
    reflectance.

    Parameters
    ----------
    mask : np.ndarray
        ``(height, width)`` bool, the matte.
    rgb : np.ndarray, optional
        ``(height, width, 3)`` the linear photograph; needed for the highlight test.
    highlight_factor : float, optional
        Luminance over the median that makes a pixel a highlight's core (its region reaches down
        to a quarter of that); ``None``: keep every pixel.
    """
    inner = ndimage.binary_erosion(mask)
    inner = inner if inner.sum() >= max(16, mask.sum() // 4) else np.asarray(mask, bool)
    if rgb is None or highlight_factor is None:
        return inner
    from skimage.filters import apply_hysteresis_threshold

    lum = luminance(np.asarray(rgb, np.float64))
    high = highlight_factor * np.median(lum[inner])
    return inner & ~apply_hysteresis_threshold(np.where(inner, lum, 0.0), high / 4.0, high)


def _fit_lighting(folder: Path, rgb: np.ndarray, inner: np.ndarray, view: dict,
                  fitted_env: np.ndarray, seen: np.ndarray, trust: dict,
                  syn: SynthesisSettings) -> np.ndarray:
    """The unseen light as a smooth map (:mod:`~abs.resynthesis.lighting`), full resolution,
    fitted on the pixels ``inner`` (:func:`fit_mask`)."""
    from abs.render import Camera, compile_scene
    from abs.render.environment import Environment
    from abs.scene import load_scene

    n_theta, n_phi = syn.light_grid
    small = 64  # the hats are smooth: their renderings need no finer map
    basis = hat_basis(small, n_theta, n_phi)
    unseen_small = ~frustum_texels(view["K"], inner.shape, small)
    path = write_scene_file(folder, "lighting.toml",
                            current_material(trust["reflectance"], trust["roughness"]),
                            syn.light_spp, syn.max_depth)
    compiled = compile_scene(load_scene(path))
    camera = Camera(view["K"], view["R"], view["t"], inner.shape[1], inner.shape[0])

    def lit_by(latlong: np.ndarray) -> np.ndarray:
        compiled.environment = Environment(latlong)
        return np.asarray(compiled.render(camera, syn.light_spp, seed=syn.seed + 11).numpy())[inner]

    fixed = lit_by(np.where(seen[..., None], fitted_env, 0.0))
    responses = np.stack([lit_by(np.repeat((b * unseen_small)[..., None], 3, axis=2))
                          for b in basis])
    small_env = cv2.resize(np.ascontiguousarray(fitted_env), (2 * small, small),
                           interpolation=cv2.INTER_AREA)
    prior = hat_averages(small_env, basis, unseen_small)
    gains = solve_gains(rgb[inner], fixed, responses, prior, syn.light_ridge)
    trust["lighting"] = {"grid": [n_theta, n_phi], "prior": prior.tolist(), "gains": gains.tolist()}
    return map_from_gains(gains, fitted_env.shape[0], n_theta, n_phi)


def _coating_under_sun(compiled, camera, samples: int = 4):
    """``render(direction) -> (height, width, 3)``: the compiled scene's object (the bare coating:
    the current plastic with reflectance 0) lit by a directional sun of unit irradiance from
    world ``direction``, seen by ``camera``.

    Evaluated, not path traced: per pixel ``samples`` x ``samples`` stratified rays hit the mesh
    once, and each direction costs one BSDF evaluation and one shadow ray per hit, the coating's
    ``f cos`` exactly. A path tracer lighting the coating by a sun of a few texels in a map had
    sparkles tens of times the highlight at 32 spp (RMSE 3.6-7.0 against a sphere's highlight
    for GGX 0.02, where the lobe of the true 0.05 left 0.5-0.8), and the candidates' comparison
    went to whichever roughness they favoured.
    """
    import drjit as dr
    import mitsuba as mi

    scene = mi.load_dict(compiled.mitsuba_dict(include_environment=False))
    w, h, n = camera.width, camera.height, samples
    idx = dr.arange(mi.UInt32, w * h * n * n)
    pixel, sub = idx // (n * n), idx % (n * n)
    # Pixel (i, j) spans [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5] (docs/conventions.md).
    u = mi.Float(pixel % w) - 0.5 + (mi.Float(sub % n) + 0.5) / n
    v = mi.Float(pixel // w) - 0.5 + (mi.Float(sub // n) + 0.5) / n
    origin, d = camera.rays(u, v)
    si = scene.ray_intersect(mi.Ray3f(origin, d))
    hit = si.is_valid()
    context = mi.BSDFContext()

    def render(direction: np.ndarray) -> np.ndarray:
        sun = mi.Vector3f(*[float(x) for x in np.asarray(direction) / np.linalg.norm(direction)])
        lit = hit & ~scene.ray_test(si.spawn_ray(sun), hit)
        value = dr.select(lit, si.bsdf().eval(context, si, si.to_local(sun), lit), 0.0)
        image = np.stack([np.asarray(value.x), np.asarray(value.y), np.asarray(value.z)], axis=-1)
        return image.reshape(h, w, n * n, 3).mean(axis=2)

    return render


def _highlight_roughness(rgb: np.ndarray, inner: np.ndarray, compared: np.ndarray, view: dict,
                         vertices: np.ndarray, faces: np.ndarray, reflectance, environment,
                         candidates: tuple[float, ...], syn: SynthesisSettings) -> dict | None:
    """The candidate roughness whose coating lobe, lit by a fitted sun, best reproduces the
    highlight left out of the fits (:mod:`~abs.resynthesis.highlight`); ``None`` without one.

    Parameters
    ----------
    inner, compared : np.ndarray
        The matte less its outline (:func:`fit_mask` without highlights) and the pixels the fits
        compared; the highlight is their difference.
    reflectance, environment :
        The fitted plastic's reflectance and the fitted map, which light every candidate.
    candidates : tuple of float
        The roughnesses tested.
    """
    from abs.render import Camera, compile_scene
    from abs.resynthesis.highlight import MIN_HIGHLIGHT_PIXELS, fit_sun, mirror_direction
    from abs.scene import load_scene

    highlight = inner & ~compared
    if highlight.sum() < MIN_HIGHLIGHT_PIXELS:
        return None
    lum = luminance(np.asarray(rgb, np.float64))
    # The sun's highlight is the region holding the most light, not the brightest pixel: a
    # photograph's (or a rendering's) single-pixel sparkles can be brighter.
    labels, count = ndimage.label(highlight, structure=np.ones((3, 3)))
    energy = ndimage.sum(lum, labels, index=np.arange(1, count + 1))
    brightest = labels == 1 + int(np.argmax(energy))
    peak = np.unravel_index(np.argmax(np.where(brightest, lum, -np.inf)), lum.shape)
    start = mirror_direction(vertices, faces, view["K"], view["R"], peak)
    h, w = inner.shape
    camera = Camera(view["K"], view["R"], view["t"], w, h)
    fits = {}
    with tempfile.TemporaryDirectory(prefix="abs-edit-") as tmp:
        folder = Path(tmp)
        write_mesh(folder, vertices, faces, view["R"], view["t"])
        write_environment(folder, environment)
        for roughness in candidates:
            scene = write_scene_file(folder, f"current_{roughness:g}.toml",
                                     current_material(reflectance, roughness), syn.sun_spp,
                                     syn.max_depth)
            current = compile_scene(load_scene(scene)).render(camera, syn.sun_spp,
                                                              seed=syn.seed + 13)
            residual = (rgb - np.asarray(current.numpy()))[inner]
            coating = compile_scene(load_scene(write_scene_file(
                folder, f"coating_{roughness:g}.toml", current_material([0.0] * 3, roughness),
                syn.sun_spp, syn.max_depth)))
            render = _coating_under_sun(coating, camera)
            fits[roughness] = fit_sun(residual, lambda d, render=render: render(d)[inner], start)
    best = min(fits, key=lambda r: fits[r].rmse)
    return {"roughness": best, "pixels": int(highlight.sum()),
            "rmse": {f"{r:g}": fits[r].rmse for r in fits},
            "sun_direction": fits[best].direction.tolist(),
            "sun_irradiance": fits[best].irradiance.tolist()}


def composite(photo: np.ndarray, mask: np.ndarray, new: np.ndarray, current: np.ndarray | None,
              differential: bool) -> np.ndarray:
    """The edited photograph: inside ``mask`` the rendering of the target, outside the photograph.

    Parameters
    ----------
    photo, new, current : np.ndarray
        ``(height, width, 3)`` linear: the photograph, the target's and the fitted current
        material's renderings (same camera and seed); ``current`` only for ``differential``.
    mask : np.ndarray
        ``(height, width)`` bool, the object's matte.
    differential : bool
        ``photo + new - current`` inside the mask (module docstring, step 5) instead of ``new``.
    """
    if differential and current is None:
        raise ValueError("differential compositing needs the current material's rendering")
    inside = photo + new - current if differential else new
    return np.where(mask[..., None], np.maximum(inside, 0.0), photo).astype(np.float32)


def _fit_candidates(folder: Path, syn: SynthesisSettings, reflectance0: np.ndarray,
                    candidates: tuple[float, ...]) -> dict:
    """Fit reflectance and environment scale for each candidate roughness: ``{roughness:
    FitResult}``."""
    from abs.fitting import FitSettings, fit

    settings = FitSettings(spp=syn.fit_spp, max_iterations=syn.max_iterations,
                           refinement_steps=syn.refinement_steps, seed=syn.seed,
                           eval_spp=syn.fit_spp)
    fits = {}
    for roughness in candidates:
        scene = write_scene_file(folder, f"fit_{roughness:g}.toml",
                                 current_material(reflectance0, roughness), syn.fit_spp,
                                 syn.max_depth)
        fits[roughness] = fit(scene, folder / "capture",
                              ["material.reflectance", "environment.scale"], settings)
    return fits


def _smallest_residual(fits: dict) -> float:
    return min(fits, key=lambda r: fits[r].metrics["train_rmse"]["after"])


def _summary(fits: dict, roughness: float) -> dict:
    """The trust record of the fit of ``roughness`` among the candidates' ``fits``."""
    result = fits[roughness]
    stderr = result.vector.split(result.uncertainty.stderr)
    return {"roughness": roughness,
            "reflectance": result.values["material.reflectance"].tolist(),
            "reflectance_stderr": stderr["material.reflectance"].tolist(),
            "scale": float(result.values["environment.scale"][0]),
            "scale_stderr": float(stderr["environment.scale"][0]),
            "residual_rmse": result.metrics["train_rmse"]["after"],
            "initial_rmse": result.metrics["train_rmse"]["before"],
            "noise": result.image_noise,
            "candidates": {f"{r:g}": fits[r].metrics["train_rmse"]["after"] for r in fits},
            "checks": list(result.checks)}


@dataclass
class FittedScene:
    """The photograph explained: everything needed to render the object with another material.

    Attributes
    ----------
    view : dict
        The camera (``name``, ``K``, ``R``, ``t``; :func:`~abs.resynthesis.studio.photo_camera`).
    shape : tuple of int
        ``(height, width)`` of the photograph.
    vertices, faces : np.ndarray
        The inflated mesh, camera frame, metres.
    environment : np.ndarray
        The fitted lat-long map (backdrop as photographed, the rest scaled by the fit).
    trust : dict
        The fit: roughness, reflectance and scale with standard errors, residual RMSE, noise,
        the candidates' residuals, the fit's checks.
    """

    view: dict
    shape: tuple[int, int]
    vertices: np.ndarray
    faces: np.ndarray
    environment: np.ndarray
    trust: dict

    @property
    def diameter_m(self) -> float:
        """The mesh's largest extent along a camera axis, metres."""
        return float(np.ptp(self.vertices, axis=0).max())


def fit_photograph(rgb: np.ndarray, mask: np.ndarray, est: Estimates,
                   syn: SynthesisSettings) -> FittedScene:
    """Steps 1-3 of the module docstring: the scene that explains the photograph.

    Parameters
    ----------
    rgb, mask : np.ndarray
        The checked photograph ``(height, width, 3)`` and matte ``(height, width)``.
    est : Estimates
        The baseline's estimates (:func:`abs.editing.edit.estimate`).
    syn : SynthesisSettings
    """
    h, w = mask.shape
    view = photo_camera((h, w), syn.fov_deg)
    vertices, faces = inflated_mesh(mask, view["K"], syn.distance_m, syn.relief)
    map_height = syn.map_height or int(np.clip(np.ceil(h * 180.0 / syn.fov_deg), 256, 2048))
    environment, seen = environment_with_backdrop(est.environment, est.background, view["K"],
                                                  map_height)
    compared = fit_mask(mask, rgb, syn.highlight_factor)  # what the fits compare
    with tempfile.TemporaryDirectory(prefix="abs-edit-") as tmp:
        folder = Path(syn.folder) if syn.folder else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        write_mesh(folder, vertices, faces, view["R"], view["t"])
        write_capture(folder / "capture", view, rgb, compared)
        write_environment(folder, environment)
        fits = _fit_candidates(folder, syn, _initial_reflectance(rgb, mask, environment),
                               syn.roughness_candidates)

        def explain(roughness: float) -> tuple[dict, np.ndarray]:
            """The candidate's fit, then the unseen light fitted to it and the fit again under
            that light: the trust record and the fitted map."""
            trust = _summary(fits, roughness)
            # The unseen part of the map carries the fitted scale; the backdrop is measured.
            fitted_env = np.where(seen[..., None], environment, environment * trust["scale"])
            if min(syn.light_grid) == 0:
                return trust, fitted_env
            unseen = _fit_lighting(folder, rgb, compared, view, fitted_env, seen, trust, syn)
            write_environment(folder, np.where(seen[..., None], environment, unseen))
            first = trust
            trust = _summary(_fit_candidates(folder, syn, np.asarray(first["reflectance"]),
                                             (roughness,)), roughness)
            trust["first_fit"] = {k: first[k] for k in ("residual_rmse", "scale", "reflectance",
                                                        "candidates")}
            trust["lighting"] = first["lighting"]
            return trust, np.where(seen[..., None], environment, unseen * trust["scale"])

        trust, fitted_env = explain(_smallest_residual(fits))
        chosen_by = {"roughness_from": "residual"}
        if syn.highlight_roughness:
            # Every candidate under the fitted light and reflectance: what differs is the lobe.
            # (With one candidate this only fits the sun, which gloss edits are lit by.)
            choice = _highlight_roughness(rgb, fit_mask(mask), compared, view, vertices, faces,
                                          trust["reflectance"], fitted_env,
                                          syn.roughness_candidates, syn)
            if choice is not None:
                chosen_by = {"roughness_from": "highlight" if len(fits) > 1 else "residual",
                             "highlight": choice}
                if choice["roughness"] != trust["roughness"]:
                    chosen_by["residual_choice"] = trust["roughness"]
                    trust, fitted_env = explain(choice["roughness"])
                    # The sun again, under the light and reflectance now fitted for it.
                    again = _highlight_roughness(rgb, fit_mask(mask), compared, view, vertices,
                                                 faces, trust["reflectance"], fitted_env,
                                                 (choice["roughness"],), syn)
                    if again is not None:
                        choice.update({k: again[k] for k in ("sun_direction", "sun_irradiance")})
        trust.update(chosen_by)
    level = float(np.mean(luminance(rgb)[mask]))
    trust.update(noise_ratio=trust["residual_rmse"] / max(trust["noise"], 1e-12),
                 relative_residual=trust["residual_rmse"] / max(level, 1e-12),
                 fov_deg=syn.fov_deg,
                 highlight_pixels_left_out=int(fit_mask(mask).sum() - compared.sum()))
    return FittedScene(view, (h, w), vertices, faces, fitted_env.astype(np.float32), trust)


def render_material(fitted: FittedScene, material: dict, syn: SynthesisSettings) -> np.ndarray:
    """Render the fitted scene with the object of scene-file material ``material``.

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` float32 linear radiance (``syn.render_spp``, seed ``syn.seed + 7``).
    """
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    h, w = fitted.shape
    view = fitted.view
    with tempfile.TemporaryDirectory(prefix="abs-edit-") as tmp:
        folder = Path(tmp)
        write_mesh(folder, fitted.vertices, fitted.faces, view["R"], view["t"])
        write_environment(folder, fitted.environment)
        path = write_scene_file(folder, "scene.toml", material, syn.render_spp, syn.max_depth)
        image = compile_scene(load_scene(path)).render(
            Camera(view["K"], view["R"], view["t"], w, h), syn.render_spp, seed=syn.seed + 7)
        return np.asarray(image.numpy(), np.float32)


def edit_fitted(rgb: np.ndarray, mask: np.ndarray, spec: MaterialSpec, fitted: FittedScene,
                syn: SynthesisSettings, merl_dir: str | None = None) -> np.ndarray:
    """Steps 4-5: the edited photograph from a fitted scene (module docstring)."""
    trust = fitted.trust
    differential = spec.kind in KEEPS_SURFACE
    if differential and "highlight" in trust:
        # The sun fitted to the highlight lights both renderings: a gloss edit reshapes its
        # highlight, while its diffuse light (which the smooth light already holds) cancels in
        # new - current. Edits that replace the surface are rendered without it, where that
        # diffuse light would count twice.
        sun = trust["highlight"]
        fitted = replace(fitted, environment=fitted.environment + np.asarray(
            sun["sun_irradiance"], np.float32) * sun_map(fitted.environment.shape[0],
                                                         np.asarray(sun["sun_direction"])))
    current = (render_material(fitted, current_material(trust["reflectance"], trust["roughness"]),
                               syn) if differential else None)
    with tempfile.TemporaryDirectory(prefix="abs-edit-") as tmp:
        target = target_material(spec, trust["reflectance"], trust["roughness"],
                                 fitted.diameter_m, Path(tmp), merl_dir)
        if target.get("type") == "merl":
            target = {**target, "file": str(Path(tmp) / target["file"])}
        new = render_material(fitted, target, syn)
    return composite(rgb, mask, new, current, differential)


def _settings(settings: EditSettings) -> SynthesisSettings:
    syn = settings.synthesis or SynthesisSettings()
    if not isinstance(syn, SynthesisSettings):
        raise InputError(None, "settings.synthesis", f"expected SynthesisSettings, got "
                                                     f"{type(syn).__name__}")
    return syn


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
        object's mean luminance, fitted values with standard errors, the candidates' residuals);
        ``environment`` the fitted map.
    """
    syn = _settings(settings)
    check_target(spec)  # refuse before the fit, not after it
    fitted = fit_photograph(rgb, mask, est, syn)
    image = edit_fitted(rgb, mask, spec, fitted, syn, settings.merl_dir)
    return EditResult(image, spec, mask, replace(est, environment=fitted.environment), settings,
                      "synthesis", fitted.trust)
