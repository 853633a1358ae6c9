"""An independence Metropolis-Hastings sampler with a Laplace (Gaussian) proposal.

Proposals ``theta' ~ N(mean, scale^2 cov)`` do not depend on the current state; a proposal is
accepted with probability ``min(1, p(theta') q(theta) / (p(theta) q(theta')))``. When the
posterior is close to the Laplace approximation of a fit (few parameters, many pixels) nearly
every proposal is accepted and successive samples are almost independent, so it needs far fewer
evaluations per effective sample than the ensemble sampler; when the approximation is poor
(skewed or multi-modal posteriors, a wrong fit), acceptance collapses, which its acceptance
fraction shows. ``scale > 1`` keeps the proposal's tails heavier than the posterior's, as the
sampler requires for a geometric rate of convergence. The benchmark
``benchmarks/sampling_efficiency.py`` compares it with emcee.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["IndependenceRun", "independence_sampler"]


@dataclass(frozen=True)
class IndependenceRun:
    """Chain (N, P), its log-posterior (N,), and the acceptance fraction."""

    chain: np.ndarray
    log_prob: np.ndarray
    acceptance_fraction: float


def independence_sampler(log_prob: Callable[[np.ndarray], float], mean: np.ndarray,
                         cov: np.ndarray, steps: int, scale: float = 1.3,
                         seed: int = 0) -> IndependenceRun:
    """Run ``steps`` proposals (one log-posterior evaluation each) starting at ``mean``.

    Parameters
    ----------
    log_prob : callable
        ``theta (P,) -> float``.
    mean, cov : ndarray
        The Laplace approximation (physical units).
    scale : float
        Proposal standard deviations are ``scale`` times the Laplace ones.
    """
    rng = np.random.default_rng(seed)
    chol = np.linalg.cholesky(np.asarray(cov, np.float64) * scale ** 2)
    inv = np.linalg.inv(chol)

    def log_q(theta):
        z = inv @ (theta - mean)
        return -0.5 * float(z @ z)

    current = np.asarray(mean, np.float64)
    lp, lq = log_prob(current), log_q(current)
    chain, lps, accepted = np.empty((steps, current.size)), np.empty(steps), 0
    for i in range(steps):
        proposal = mean + chol @ rng.normal(size=current.size)
        lp_new = log_prob(proposal)
        lq_new = log_q(proposal)
        if np.log(rng.uniform()) < (lp_new - lp) - (lq_new - lq):
            current, lp, lq = proposal, lp_new, lq_new
            accepted += 1
        chain[i], lps[i] = current, lp
    return IndependenceRun(chain, lps, accepted / steps)
