"""Reflectance models of the thesis, as predictions of ``f_r cos(theta_l)`` (1/sr).

Parameters broadcast against the cosines: ``p`` of shape (k, C, 1) with cosines of shape (M,)
gives (C, M), every channel at once (the fits use this). Every model is isotropic and takes the
cosines of :class:`~abs.lightstage.normalise.Isotropic`:
``cos_l = n.l``, ``cos_v = n.v``, ``cos_h = n.h``. Parameters are per colour channel:

- Lambert ``(kd,)``: ``kd / pi``; ``kd`` the diffuse albedo.
- Blinn-Phong ``(kd, ks, e)``: ``kd / pi + ks (e + 8) / (8 pi) cos_h^e``, the energy-normalised
  form, so ``ks`` is a specular albedo and does not trade off against the exponent ``e``.
- Cook-Torrance ``(kd, ks, alpha)``: ``kd / pi + ks D(h) G(l, v) / (4 cos_l cos_v)`` with the GGX
  (Trowbridge-Reitz) distribution ``D`` and the separable Smith-GGX masking ``G`` of roughness
  ``alpha``; Fresnel is taken as a constant folded into ``ks`` (a light stage around one camera
  sees too few grazing angles to fit an index).

:func:`blinn_phong_to_alpha` is the usual Beckmann/Blinn-Phong correspondence
``alpha = sqrt(2 / (e + 2))`` (Walter et al. 2007), used to start Cook-Torrance from a Blinn-Phong fit.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MODELS", "lambert", "blinn_phong", "cook_torrance", "blinn_phong_to_alpha", "evaluate"]


def lambert(p: np.ndarray, cos_l: np.ndarray, cos_v: np.ndarray, cos_h: np.ndarray) -> np.ndarray:
    """``f_r cos_l`` of Lambert with ``p = (kd,)``."""
    return p[0] / np.pi * np.maximum(cos_l, 0.0)


def blinn_phong(p: np.ndarray, cos_l: np.ndarray, cos_v: np.ndarray, cos_h: np.ndarray) -> np.ndarray:
    """``f_r cos_l`` of normalised Blinn-Phong with ``p = (kd, ks, e)``."""
    kd, ks, e = p[0], p[1], p[2]
    spec = ks * (e + 8.0) / (8.0 * np.pi) * np.minimum(np.maximum(cos_h, 0.0), 1.0) ** e
    return (kd / np.pi + spec) * np.maximum(cos_l, 0.0)


def _ggx_g1(c: np.ndarray, a2: float) -> np.ndarray:
    c = np.minimum(np.maximum(c, 1e-6), 1.0)
    return 2.0 * c / (c + np.sqrt(a2 + (1.0 - a2) * c * c))


def cook_torrance(p: np.ndarray, cos_l: np.ndarray, cos_v: np.ndarray, cos_h: np.ndarray) -> np.ndarray:
    """``f_r cos_l`` of Cook-Torrance (GGX, Smith) with ``p = (kd, ks, alpha)``."""
    kd, ks, alpha = p[0], p[1], p[2]
    a2 = alpha * alpha
    ch = np.minimum(np.maximum(cos_h, 0.0), 1.0)
    d = a2 / (np.pi * (ch * ch * (a2 - 1.0) + 1.0) ** 2)
    cl = np.maximum(cos_l, 0.0)
    cv = np.maximum(cos_v, 1e-6)
    g = _ggx_g1(cl, a2) * _ggx_g1(cv, a2)
    # f_r cos_l = ... D G / (4 cos_l cos_v) * cos_l: the cos_l cancels, kept finite at grazing light.
    return kd / np.pi * cl + ks * d * g / (4.0 * cv) * (cl > 0)


def blinn_phong_to_alpha(exponent: np.ndarray | float) -> np.ndarray:
    """Roughness ``alpha = sqrt(2 / (e + 2))`` matching a Blinn-Phong exponent ``e``."""
    return np.sqrt(2.0 / (np.asarray(exponent, dtype=np.float64) + 2.0))


MODELS = {"lambert": lambert, "blinn_phong": blinn_phong, "cook_torrance": cook_torrance}
"""Model functions by name."""

PARAMETERS = {"lambert": ("kd",), "blinn_phong": ("kd", "ks", "exponent"),
              "cook_torrance": ("kd", "ks", "alpha")}
"""Parameter names by model."""


def evaluate(model: str, params: np.ndarray, cos_l: np.ndarray, cos_v: np.ndarray,
             cos_h: np.ndarray) -> np.ndarray:
    """``f_r cos_l`` (N, 3) for per-measurement parameters ``params`` (N, 3 channels, k)."""
    fn = MODELS[model]
    return np.stack([fn(np.moveaxis(params[:, c, :], 1, 0), cos_l, cos_v, cos_h) for c in range(3)], 1)
