"""Uncertainty of a fit by the Laplace (Gauss-Newton) approximation.

Near the optimum the posterior of the physical parameters is approximately Gaussian with
precision ``H = J^T J / sigma^2 + diag(1 / prior_sd^2)``, ``J`` the Jacobian of the pixel
residuals (from the renderer's forward-mode derivatives) and ``sigma`` the pixel noise. ``sigma``
is estimated from the residuals at the optimum, ``sigma^2 = |r|^2 / (M - P)``, so it contains the
photographs' noise, the renderer's Monte-Carlo noise and any model error alike: the standard
errors are those of a model that explains the photographs up to white noise of that size. When
the estimate's Monte-Carlo error is measured and added (:func:`with_monte_carlo_error`), the
renders' noise is left out of ``sigma`` (two independent renders' residuals, ``residuals2``).
Correlations near +-1 mean the photographs cannot separate two parameters (they trade off).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["LaplaceApproximation", "laplace", "with_monte_carlo_error", "with_extra_covariance",
           "monte_carlo_spread", "lag1_autocorrelation"]


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
        Estimated residual standard deviation per pixel and channel (linear RGB): with
        ``residuals2``, of the noise-free residual (:func:`laplace`).
    identifiable : ndarray of bool, shape (P,)
    """

    covariance: np.ndarray
    stderr: np.ndarray
    correlation: np.ndarray
    pixel_sigma: float
    identifiable: np.ndarray


def _from_covariance(cov: np.ndarray, pixel_sigma: float, identifiable: np.ndarray) -> LaplaceApproximation:
    stderr = np.sqrt(np.maximum(np.diag(cov), 0.0))
    stderr[~identifiable] = np.nan
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = cov / np.outer(stderr, stderr)
    np.fill_diagonal(correlation, 1.0)
    return LaplaceApproximation(cov, stderr, correlation, pixel_sigma, identifiable)


def monte_carlo_spread(points: np.ndarray, scatter: np.ndarray | None = None) -> np.ndarray:
    """The iterates (m, P) whose scatter measures the Monte-Carlo error of the mean of ``points``
    (n, P): ``points`` themselves, or ``scatter`` when fewer than three points were averaged and
    ``scatter`` holds more (one or two arrived points say nothing of their spread; iterates that
    include some of the approach scatter more, so the error comes out conservative rather than
    missing). Fewer than two rows: the error cannot be measured."""
    points = np.atleast_2d(np.asarray(points, np.float64))
    if points.shape[0] < 3 and scatter is not None and np.atleast_2d(scatter).shape[0] > points.shape[0]:
        return np.atleast_2d(np.asarray(scatter, np.float64))
    return points


#: Fewest sequential points from which a lag-1 autocorrelation is estimated.
_AUTOCORRELATION_POINTS = 6
#: Largest lag-1 autocorrelation used (a walk estimated from a dozen points).
_MAX_AUTOCORRELATION = 0.9


def lag1_autocorrelation(points: np.ndarray) -> np.ndarray:
    """Lag-1 autocorrelation of each coordinate of the sequence ``points`` (n, P); 0 for a
    coordinate that does not vary."""
    x = np.atleast_2d(np.asarray(points, np.float64))
    x = x - x.mean(axis=0)
    var = np.sum(x * x, axis=0)
    return np.where(var > 0, np.sum(x[1:] * x[:-1], axis=0) / np.where(var > 0, var, 1.0), 0.0)


def with_extra_covariance(approx: LaplaceApproximation, extra: np.ndarray) -> LaplaceApproximation:
    """``approx`` with the covariance ``extra`` (P, P) of an independent error added (an
    estimate's Monte-Carlo error)."""
    return _from_covariance(approx.covariance + extra, approx.pixel_sigma, approx.identifiable)


def with_monte_carlo_error(approx: LaplaceApproximation, points: np.ndarray,
                          scatter: np.ndarray | None = None,
                          sequential: bool = False) -> LaplaceApproximation:
    """Add the Monte-Carlo error of an estimate that is the mean of ``points`` (n, P).

    The refinement's estimate is the mean of iterates that scatter around the solution because
    each step sees a different noisy render; the covariance of that mean,
    ``cov(spread) / n``, is added to the Laplace covariance, ``spread`` being
    :func:`monte_carlo_spread` of ``points`` and ``scatter`` (with fewer than three rows only its
    diagonal, a covariance from two points being rank one; with fewer than two nothing).

    ``sequential``: the points are successive iterates, not independent draws. Full Newton steps
    on fresh renders scatter independently (the glass suite's spheres: lag-1 autocorrelation
    -0.5 to -0.1 in the IOR), but steps cut to a trust radius walk, and the mean of a walk varies
    far more than ``cov / n`` says (the suite's distant bowl before this correction:
    autocorrelation 0.72, IOR 1.459 +- 0.018 for 1.52; with it, in the next run, 1.474 +- 0.11). A coordinate whose autocorrelation ``rho`` is positive has its
    variance of the mean multiplied by ``(1 + rho) / (1 - rho)`` (an AR(1) series' effective
    sample size), from :data:`_AUTOCORRELATION_POINTS` points on.
    """
    n = np.atleast_2d(points).shape[0]
    spread = monte_carlo_spread(points, scatter)
    if spread.shape[0] < 2:
        return approx
    extra = np.atleast_2d(np.cov(spread, rowvar=False)) / n
    if spread.shape[0] < 3:
        extra = np.diag(np.diag(extra))
    if sequential and spread.shape[0] >= _AUTOCORRELATION_POINTS:
        rho = lag1_autocorrelation(spread)
        # The sample autocorrelation of a short series is biased low by about (1 + 3 rho) / m
        # (Kendall); corrected, a walk's mean is covered 80 % of the time at 95 % intervals
        # from 12 points with rho 0.7 (65 % uncorrected, 53 % with cov / n alone).
        rho = np.clip(rho + (1 + 3 * rho) / spread.shape[0], 0.0, _MAX_AUTOCORRELATION)
        inflation = np.sqrt((1 + rho) / (1 - rho))
        extra = extra * np.outer(inflation, inflation)
    return with_extra_covariance(approx, extra)


def laplace(residuals: np.ndarray, jacobian: np.ndarray, prior_sd: np.ndarray | None = None,
            jacobian2: np.ndarray | None = None,
            more_pairs: Sequence[tuple[np.ndarray, np.ndarray]] = (),
            curvatures: Sequence[np.ndarray] = (),
            residuals2: np.ndarray | None = None,
            correlation=None) -> LaplaceApproximation:
    """Laplace approximation from residuals (M,) and their Jacobian (M, P) at the optimum.

    Parameters
    ----------
    prior_sd : ndarray, shape (P,), optional
        Gaussian prior standard deviations (``inf`` where a scalar has no prior).
    jacobian2 : ndarray, shape (M, P), optional
        A second Jacobian from an independent render: the curvature is then
        ``(J1^T J2 + J2^T J1) / 2``, which is not inflated by the Jacobians' Monte-Carlo noise
        (``J1^T J1`` is, and would understate the standard errors). Directions whose curvature
        this estimate cannot resolve from zero come out unidentifiable.
    more_pairs : sequence of (ndarray, ndarray), optional
        Further independent Jacobian pairs at the same point: the cross curvature is averaged
        over all pairs (a noisy column, an IOR seen through glass, can leave one pair's estimate
        unresolved where the average is not).
    curvatures : sequence of ndarray, shape (P, P)
        Further cross-curvature estimates ``(J1^T J2 + J2^T J1) / 2`` from independent pairs
        near the same point (a refinement's steps), averaged with the pairs' (needs
        ``jacobian2``).
    residuals2 : ndarray, shape (M,), optional
        The residuals of a second render independent of the first: ``sigma^2`` is then
        ``r1 . r2 / (M - P)``, whose expectation is the size of the noise-free residual (the
        photographs' noise and any model error) without the renders' own Monte-Carlo noise. Only
        for an estimate whose Monte-Carlo error is added separately
        (:func:`with_monte_carlo_error`): the renders' noise would otherwise be counted twice
        (sphere-1.52 of the glass suite at 64 spp: absorption standard errors three times as
        wide).
    correlation : callable, optional
        ``K @ X`` for (M, n) matrices, ``K`` the correlation of the pixel noise between residuals
        (:meth:`abs.model.FitProblem.noise_correlation`; mean diagonal 1). The least-squares
        estimate's covariance is then the sandwich ``H^-1 (J^T K J / sigma^2) H^-1`` instead of
        ``H^-1``: a built photograph's demosaicing spreads each site's noise over neighbouring
        pixels, which then carry less independent information than their number says.
    """
    m, p = jacobian.shape
    other = residuals if residuals2 is None else residuals2
    # Floored: at many samples a two-seed product can come out at or below zero when the
    # photographs are nearly noise-free (the Laplace part is then negligible, not negative).
    sigma2 = max(float(residuals @ other), 1e-6 * float(residuals @ residuals)) / max(m - p, 1)
    if jacobian2 is None:
        curvature = jacobian.T @ jacobian
    else:
        pairs = [(jacobian, jacobian2), *more_pairs]
        curvature = np.mean([0.5 * (a.T @ b + b.T @ a) for a, b in pairs]
                            + [np.asarray(h, np.float64) for h in curvatures], axis=0)
    precision = curvature / max(sigma2, 1e-300)
    if prior_sd is not None:
        precision = precision + np.diag(1.0 / np.square(np.asarray(prior_sd, np.float64)))
    # Eigen-decomposition: directions with (numerically) zero curvature are not identifiable.
    # Of the precision scaled to unit diagonal, so that a scalar's units do not decide it (an
    # environment scale in data numbers per second, ~1e5, against an IOR: their curvatures
    # differ by 1e10 and the scale came out "singular").
    d = np.sqrt(np.maximum(np.diag(precision), 0.0))
    d = np.where(d > 0, d, 1.0)
    w, V = np.linalg.eigh(precision / np.outer(d, d))
    floor = max(float(w.max()), 1e-300) * 1e-10
    good = w > floor
    inv = ((V[:, good] / w[good]) @ V[:, good].T) / np.outer(d, d)
    if correlation is not None:
        # The "meat" from independent Jacobians, as the curvature (J1^T K J2 is not inflated by
        # their Monte-Carlo noise).
        pairs = [(jacobian, jacobian2 if jacobian2 is not None else jacobian), *more_pairs]
        meat = np.mean([0.5 * (a.T @ correlation(b) + (a.T @ correlation(b)).T) for a, b in pairs],
                       axis=0) / max(sigma2, 1e-300)
        if prior_sd is not None:
            meat = meat + np.diag(1.0 / np.square(np.asarray(prior_sd, np.float64)))
        inv = inv @ meat @ inv
    # A scalar is unidentifiable when a tenth or more of it lies in unresolved directions; a
    # small share (a scale's 1 % in an IOR's unresolved direction) leaves it resolved, its
    # standard error from the resolved directions.
    weak = np.sum(np.square(V[:, ~good]), axis=1) > 0.1 if (~good).any() else np.zeros(p, bool)
    return _from_covariance(inv, float(np.sqrt(sigma2)), ~weak)
