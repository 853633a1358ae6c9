"""Frames of the light stage rendered from reflectance: fitted per-point models, or analytic truth.

The same direct-lighting model as :mod:`~abs.lightstage.measure`, run forwards: one ray per pixel
centre, one shadow ray to the LED, ``pixel = clip(gain * exposure * I (level/255) att / d^2 *
f_r cos(theta_l), 0, 1)``, black where the ray misses the object. No inter-reflection, no
global light, no sensor noise.

Used twice: to render held-out views and lights from the fitted per-point models (the thesis's
validation), and by the benchmark to make the frames of a synthetic object with known analytic
reflectance (:class:`AnalyticMaterial`). Because both use this one model, the benchmark tests
measurement, normalisation, binning and fitting, not the forward model itself; that is the
documented limit of the synthetic proof.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from abs.lightstage.fit import ModelFits
from abs.lightstage.geometry import RigGeometry
from abs.lightstage.measure import PoseView, led_irradiance
from abs.lightstage.models import MODELS, evaluate
from abs.lightstage.normalise import normalise
from abs.lightstage.raycast import MeshTracer
from abs.lightstage.surface import SurfacePoints

__all__ = ["Reflectance", "AnalyticMaterial", "MeasuredRegions", "fitted_reflectance", "render_view", "mae"]

Reflectance = Callable[[PoseView, np.ndarray], np.ndarray]
"""``reflectance(view, wi)``: ``f_r cos(theta_l)`` (N, 3), 1/sr, at the hits of ``view`` lit from
unit directions ``wi`` (N, 3)."""


@dataclass(frozen=True)
class AnalyticMaterial:
    """A spatially varying analytic material: one model, parameters a function of object position.

    Parameters
    ----------
    model : str
        ``lambert``, ``blinn_phong`` or ``cook_torrance``.
    params_at : callable
        ``params_at(points)``: (N, 3 channels, k) parameters at object-frame points (N, 3), metres.
    """

    model: str
    params_at: Callable[[np.ndarray], np.ndarray]

    def __call__(self, view: PoseView, wi: np.ndarray) -> np.ndarray:
        iso = normalise(view.hits.normal, wi, view.view)
        return evaluate(self.model, self.params_at(view.hits.point), iso.cos_l, iso.cos_v, iso.cos_h)


@dataclass(frozen=True)
class MeasuredRegions:
    """An object made of regions of measured (data-driven, isotropic) materials.

    Parameters
    ----------
    region_at : callable
        ``region_at(points)``: (N,) region index at object-frame points (N, 3), metres.
    brdfs : tuple of callable
        Per region, ``brdf(theta_h, theta_d, phi_d)``: (N, 3) BRDF in 1/sr at Rusinkiewicz angles
        (radians), e.g. :func:`abs.brdf.nbrdf.evaluate_nbrdf` bound to one MERL material's network.
    """

    region_at: Callable[[np.ndarray], np.ndarray]
    brdfs: tuple[Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray], ...]

    def __call__(self, view: PoseView, wi: np.ndarray) -> np.ndarray:
        iso = normalise(view.hits.normal, wi, view.view)
        region = np.asarray(self.region_at(view.hits.point))
        out = np.zeros((len(region), 3))
        for r, brdf in enumerate(self.brdfs):
            sel = region == r
            if sel.any():
                out[sel] = brdf(iso.theta_h[sel], iso.theta_d[sel], iso.phi_d[sel])
        return out * np.clip(iso.cos_l, 0.0, None)[:, None]


def fitted_reflectance(fits: ModelFits, model: str, points: SurfacePoints) -> Reflectance:
    """The per-point fitted ``model`` as a :data:`Reflectance`.

    A point with too few fitting measurements to be fitted (seen rarely, or only in held-out
    frames) takes the parameters of the nearest fitted point, as a renderer of the fitted object
    would have to; the object renders black only when no point is fitted at all.
    """
    from scipy.spatial import cKDTree

    assert model in MODELS, model
    params = np.nan_to_num(fits.params[model], nan=0.0)
    fitted = np.nonzero(fits.count > 0)[0]
    if 0 < len(fitted) < len(params):
        _, nearest = cKDTree(points.position[fitted]).query(points.position)
        params = params[fitted[nearest]]

    def reflectance(view: PoseView, wi: np.ndarray) -> np.ndarray:
        pid = points.lookup(view.hits.triangle, view.hits.barycentric)
        iso = normalise(view.hits.normal, wi, view.view)
        return evaluate(model, params[pid], iso.cos_l, iso.cos_v, iso.cos_h)

    return reflectance


def render_view(geometry: RigGeometry, tracer: MeshTracer, view: PoseView, light: str, level: int,
                exposure_s: float, reflectance: Reflectance) -> np.ndarray:
    """One frame (H, W, 3) in [0, 1] of ``view`` lit by LED ``light``; 0 off the object."""
    wi, factor = led_irradiance(geometry, tracer, view, light, level)
    radiance = factor * np.clip(reflectance(view, wi), 0.0, None)
    image = np.zeros((view.shape[0] * view.shape[1], 3))
    image[view.pixel] = np.clip(geometry.gain * exposure_s * radiance, 0.0, 1.0)
    return image.reshape(view.shape[0], view.shape[1], 3)


def mae(rendered: np.ndarray, observed: np.ndarray, mask: np.ndarray) -> tuple[float, int]:
    """Thesis Eq. 4.1: mean absolute difference of pixel values in [0, 1] over the object mask.

    Returns the sum of absolute differences (over masked pixels and channels) and their count, so
    that many images pool into one mean; ``sum / count`` is the MAE of these images.
    """
    diff = np.abs(np.asarray(rendered, np.float64) - np.clip(np.asarray(observed, np.float64), 0, 1))
    sel = diff.reshape(-1, 3)[np.asarray(mask).ravel()]
    return float(sel.sum()), int(sel.size)
