"""The mode of a rendered posterior: where the chain starts.

Gauss-Newton on the chain's own log-likelihood (the crossed form of
:mod:`abs.sampling.likelihood`, same fixed seeds, same variance): with ``r_a, r_b`` the residuals
of the two fixed-seed renders and ``J_a, J_b`` their Jacobians,

    -log L = 1/2 sum r_a r_b / var,
    gradient g = 1/2 (J_a^T W r_b + J_b^T W r_a),   W = 1 / var,
    Hessian  H = 1/2 (J_a^T W J_b + J_b^T W J_a)    (cross products: no Monte-Carlo inflation).

A step is kept only if the log-posterior (prior included) rises; otherwise it is halved. The
prior's curvature is left out of ``H``: this finds a start, the chain does the rest.
"""

from __future__ import annotations

import numpy as np

from abs.sampling.posterior import ResidualPosterior

__all__ = ["find_mode"]


def find_mode(posterior, theta: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              max_steps: int = 6, tolerance: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Climb ``posterior`` (a :class:`~abs.sampling.posterior.RenderPosterior`) from ``theta``.

    Parameters
    ----------
    posterior : RenderPosterior
    theta : ndarray, shape (P,)
        Start (physical units), e.g. a fit.
    lower, upper : ndarray, shape (P,)
        Bounds; steps are clipped just inside them.
    max_steps : int
        Gauss-Newton steps at most (each renders every training view twice and its Jacobian twice).
    tolerance : float
        Stop when a step is smaller than this many Laplace standard deviations in every scalar.

    Returns
    -------
    theta : ndarray, shape (P,)
        The highest point reached.
    sd : ndarray, shape (P,)
        Laplace standard deviations there (``sqrt(diag(H^-1))``; NaN where ``H`` is singular).
    """
    problem = posterior.problem()
    weight = 1.0 / posterior.variance

    def evaluate(t: np.ndarray):
        # The log-posterior and the residuals it came from: the next step reuses them.
        rs = posterior.residuals(t)
        return ResidualPosterior(lambda _: rs, posterior.variance, posterior.prior)(t), rs

    span = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
    lo, hi = lower + 1e-6 * span, upper - 1e-6 * span
    theta = np.clip(np.asarray(theta, np.float64), lo, hi)
    current, (r_a, r_b) = evaluate(theta)
    sd = np.full(theta.size, np.nan)
    for _ in range(max_steps):
        j_a, j_b = (problem.jacobian(theta, posterior.spp, seed) for seed in posterior.seeds)
        g = 0.5 * (j_a.T @ (weight * r_b) + j_b.T @ (weight * r_a))
        h = 0.5 * (j_a.T @ (weight[:, None] * j_b) + j_b.T @ (weight[:, None] * j_a))
        try:
            step = -np.linalg.solve(h, g)
            sd = np.sqrt(np.clip(np.diag(np.linalg.inv(h)), 0.0, None))
        except np.linalg.LinAlgError:
            break
        moved = False
        for _ in range(4):
            candidate = np.clip(theta + step, lo, hi)
            value, rs = evaluate(candidate)
            if value > current:
                theta, current, (r_a, r_b), moved = candidate, value, rs, True
                break
            step = step / 2
        if not moved or np.all(np.abs(step) < tolerance * np.where(sd > 0, sd, np.inf)):
            break
    return theta, sd
