"""Fresnel reflectance of a smooth conductor (unpolarised light)."""

from __future__ import annotations

import numpy as np

__all__ = ["conductor_reflectance"]


def conductor_reflectance(cos_theta: np.ndarray, eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a metal with complex IOR ``eta + i k`` (exact).

    Parameters
    ----------
    cos_theta : ndarray
        Cosine of the angle of incidence (to the normal), in [0, 1]; shape ``(...)``.
    eta, k : array-like, shape (C,)
        Real and imaginary parts of the relative index per channel (e.g. R, G, B from
        :func:`abs.colour.optical_constants_rgb`'s ``ior_rgb`` and ``k_rgb``).

    Returns
    -------
    ndarray, shape ``(..., C)``
        ``(R_s + R_p) / 2``: 1 at grazing incidence, ``((eta-1)² + k²) / ((eta+1)² + k²)`` at
        normal incidence, the dielectric Fresnel equations at ``k = 0``.
    """
    c = np.clip(np.asarray(cos_theta, np.float64), 0.0, 1.0)[..., None]
    n = np.asarray(eta, np.float64) + 1j * np.asarray(k, np.float64)
    sin2 = 1.0 - c**2
    cos_t = np.sqrt(n**2 - sin2) / n  # cosine of the (complex) refraction angle, times 1
    rs = (c - n * cos_t) / (c + n * cos_t)
    rp = (n * c - cos_t) / (n * c + cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
