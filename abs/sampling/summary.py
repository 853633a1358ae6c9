"""Posterior summaries from an ensemble chain: mean, sd, 5-95 % interval, effective sample size.

The effective sample size follows emcee's convention: kept samples (walkers x steps after the
burn-in) divided by the integrated autocorrelation time ``tau`` (in steps) of each scalar.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["burn_in", "parameter_summary"]


def burn_in(tau: np.ndarray | None, steps: int) -> int:
    """Steps discarded as burn-in: ``2 max(tau)``, at most half the chain (half without tau)."""
    if tau is None or not np.all(np.isfinite(tau)):
        return steps // 2
    return int(min(np.ceil(2 * np.max(tau)), steps // 2))


def parameter_summary(chain: np.ndarray, names: Sequence[str], sizes: Sequence[int],
                      units: Sequence[str], tau: np.ndarray) -> dict:
    """Per-parameter statistics of a chain after burn-in.

    Parameters
    ----------
    chain : ndarray, shape (S, W, P)
        Kept steps x walkers x scalars (physical units).
    names, sizes, units : sequences
        The parameters' layout in the ``P`` scalars (``ParameterVector``'s).
    tau : ndarray, shape (P,)
        Integrated autocorrelation time per scalar (steps).

    Returns
    -------
    dict
        ``name -> {"mean", "sd", "q05", "q95", "ess", "tau", "unit"}``, lists per scalar.
    """
    flat = chain.reshape(-1, chain.shape[-1])
    mean, sd = flat.mean(axis=0), flat.std(axis=0, ddof=1)
    q05, q95 = np.quantile(flat, [0.05, 0.95], axis=0)
    ess = flat.shape[0] / np.maximum(tau, 1.0)
    out, offset = {}, 0
    for name, n, unit in zip(names, sizes, units):
        s = slice(offset, offset + n)
        offset += n
        out[name] = {"mean": mean[s].tolist(), "sd": sd[s].tolist(), "q05": q05[s].tolist(),
                     "q95": q95[s].tolist(), "ess": ess[s].tolist(), "tau": tau[s].tolist(),
                     "unit": unit}
    return out
