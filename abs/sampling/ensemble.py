"""emcee's affine-invariant ensemble sampler, run until the autocorrelation time is resolved.

The chain lives in an :class:`emcee.backends.HDFBackend` file, written after every step, so an
interrupted run loses at most one step and continues from the file's last walker positions (and
random state). The run stops at the first of:

- emcee's rule of thumb: the chain is longer than ``50 tau`` for every parameter and the estimate
  of ``tau`` (the integrated autocorrelation time, in steps) changed by less than 1 % since the
  previous check;
- ``max_steps`` steps in the file, or ``max_evaluations`` log-posterior evaluations (the render
  budget divided by the renders per evaluation).

Storage of everything else and progress display belong to the caller (``on_step``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import emcee
import numpy as np

__all__ = ["EnsembleProgress", "run_ensemble", "autocorrelation_time", "TAU_FACTOR", "TAU_RTOL"]

TAU_FACTOR = 50   # the chain must be this many autocorrelation times long
TAU_RTOL = 0.01   # ... and the estimate of tau stable to this fraction between checks


@dataclass(frozen=True)
class EnsembleProgress:
    """State of a run after a step (given to ``on_step`` and returned at the end).

    Attributes
    ----------
    steps : int
        Steps in the chain file (including those of earlier, resumed runs).
    evaluations : int
        Log-posterior evaluations behind them (walkers x (steps + 1): the start is evaluated).
    acceptance_fraction : float
        Mean over walkers.
    tau : ndarray or None
        Latest estimate of the integrated autocorrelation time per parameter (steps).
    converged : bool
    stop_reason : str or None
        ``"converged"``, ``"max_steps"`` or ``"max_evaluations"`` when the run ended.
    budget_steps : int or None
        Steps the file will hold when this run's budget (``max_steps`` or ``max_evaluations``)
        is spent, unless it converges first.
    """

    steps: int
    evaluations: int
    acceptance_fraction: float
    tau: np.ndarray | None
    converged: bool = False
    stop_reason: str | None = None
    budget_steps: int | None = None


def autocorrelation_time(backend: emcee.backends.Backend) -> np.ndarray:
    """emcee's estimate of tau per parameter (steps), without its "chain too short" error."""
    with np.errstate(invalid="ignore", divide="ignore"):  # NaN for a chain that never moved
        return np.asarray(backend.get_autocorr_time(tol=0), np.float64)


def run_ensemble(log_prob: Callable[[np.ndarray], float], backend: emcee.backends.Backend,
                 initial: np.ndarray | None, max_steps: int, max_evaluations: int | None = None,
                 pool=None, seed: int = 0, check_every: int = 20,
                 on_step: Callable[[EnsembleProgress], None] | None = None) -> EnsembleProgress:
    """Run (or continue) an ensemble chain stored in ``backend``.

    Parameters
    ----------
    log_prob : callable
        ``theta (P,) -> float`` log-posterior (``-inf`` outside the support); picklable when a
        process pool or Dask evaluates it.
    backend : emcee backend
        A fresh backend starts from ``initial``; one holding steps continues from its last sample.
    initial : ndarray, shape (W, P), or None
        Walker start positions (ignored when the backend already holds steps).
    max_steps : int
        Total steps in the chain (earlier runs included).
    max_evaluations : int, optional
        Total log-posterior evaluations (earlier runs included).
    pool : object with ``map``, optional
        Evaluates the walkers of each half-ensemble in parallel.
    seed : int
        Seed of the sampler's own random numbers (stretch moves), for a fresh chain.
    check_every : int
        Steps between autocorrelation estimates.
    """
    resuming = backend.initialized and backend.iteration > 0
    if resuming:
        walkers, ndim = backend.shape
    else:
        walkers, ndim = np.shape(initial)
        backend.reset(walkers, ndim)
    sampler = emcee.EnsembleSampler(walkers, ndim, log_prob, pool=pool, backend=backend)
    if resuming:
        state = backend.get_last_sample()
    else:
        sampler.random_state = np.random.RandomState(seed).get_state()
        state = np.asarray(initial, np.float64)

    def progress(tau, converged=False, reason=None) -> EnsembleProgress:
        it = int(backend.iteration)
        acc = float(np.mean(backend.accepted) / it) if it else 0.0
        return EnsembleProgress(it, int(walkers * (it + 1)), acc, tau, converged, reason, budget_steps)

    def budget_left() -> int:
        left = max_steps - backend.iteration
        if max_evaluations is not None:
            left = min(left, max_evaluations // walkers - 1 - backend.iteration)
        return left

    tau_old, tau = None, None
    budget_steps = int(backend.iteration) + max(budget_left(), 0)
    if budget_left() <= 0:
        return progress(None, False, "max_steps" if backend.iteration >= max_steps else "max_evaluations")
    for _ in sampler.sample(state, iterations=budget_left(), progress=False):
        it = backend.iteration
        converged = False
        if it % check_every == 0:
            tau = autocorrelation_time(backend)
            converged = bool(tau_old is not None and np.all(np.isfinite(tau))
                             and np.all(TAU_FACTOR * tau < it)
                             and np.all(np.abs(tau_old - tau) < TAU_RTOL * tau))
            tau_old = tau
        if converged:
            final = progress(tau, True, "converged")
            if on_step:
                on_step(final)
            return final
        if on_step:
            on_step(progress(tau))
    tau = autocorrelation_time(backend)
    reason = "max_steps" if backend.iteration >= max_steps else "max_evaluations"
    return progress(tau, False, reason)
