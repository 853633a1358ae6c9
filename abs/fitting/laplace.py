"""Uncertainty of a fit by the Laplace (Gauss-Newton) approximation.

Near the optimum the posterior of the physical parameters is approximately Gaussian with
precision ``H = J^T J / sigma^2 + diag(1 / prior_sd^2)``, ``J`` the Jacobian of the pixel
residuals (from the renderer's forward-mode derivatives) and ``sigma`` the pixel noise. ``sigma``
is estimated from the residuals at the optimum, ``sigma^2 = |r|^2 / (M - P)``, so it contains the
photographs' noise, the renderer's Monte-Carlo noise and any model error alike: the standard
errors are those of a model that explains the photographs up to white noise of that size.
Correlations near +-1 mean the photographs cannot separate two parameters (they trade off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LaplaceApproximation", "laplace"]


@dataclass(frozen=True)
class LaplaceApproximation:
    """Gaussian approximation of the posterior at the fit.

    Attributes
    ----------
    covariance : ndarray, shape (P, P)
        Physical units.
    stderr : ndarray, shape (P,)
        NaN for directions the photographs do not constrain (singular precision, no prior).
    correlation : ndarray, shape (P, P)
    pixel_sigma : float
        Estimated residual standard deviation per pixel and channel (linear RGB).
    identifiable : ndarray of bool, shape (P,)
    """

    covariance: np.ndarray
    stderr: np.ndarray
    correlation: np.ndarray
    pixel_sigma: float
    identifiable: np.ndarray


def laplace(residuals: np.ndarray, jacobian: np.ndarray,
            prior_sd: np.ndarray | None = None) -> LaplaceApproximation:
    """Laplace approximation from residuals (M,) and their Jacobian (M, P) at the optimum.

    Parameters
    ----------
    prior_sd : ndarray, shape (P,), optional
        Gaussian prior standard deviations (``inf`` where a scalar has no prior).
    """
    m, p = jacobian.shape
    sigma2 = float(residuals @ residuals) / max(m - p, 1)
    precision = jacobian.T @ jacobian / max(sigma2, 1e-300)
    if prior_sd is not None:
        precision = precision + np.diag(1.0 / np.square(np.asarray(prior_sd, np.float64)))
    # Eigen-decomposition: directions with (numerically) zero curvature are not identifiable.
    w, V = np.linalg.eigh(precision)
    floor = max(float(w.max()), 1e-300) * 1e-10
    good = w > floor
    inv = (V[:, good] / w[good]) @ V[:, good].T
    weak = np.abs(V[:, ~good]).max(axis=1) > 1e-3 if (~good).any() else np.zeros(p, bool)
    stderr = np.sqrt(np.maximum(np.diag(inv), 0.0))
    stderr[weak] = np.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = inv / np.outer(stderr, stderr)
    np.fill_diagonal(correlation, 1.0)
    return LaplaceApproximation(inv, stderr, correlation, float(np.sqrt(sigma2)), ~weak)
