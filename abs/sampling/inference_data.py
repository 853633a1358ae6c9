"""The chain as ArviZ InferenceData (netCDF): one variable per parameter, walkers as chains.

Walkers of an ensemble sampler are not independent chains (each move uses the others), so the
R-hat computed over them is a diagnostic of mixing between walkers, not a proof of convergence.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["arviz", "inference_data", "write_netcdf", "r_hat"]


def arviz():
    """The ``arviz`` module (imported on first use: it is slow to import)."""
    with warnings.catch_warnings():  # arviz announces its coming refactor on import
        warnings.simplefilter("ignore", FutureWarning)
        import arviz
    return arviz


def inference_data(chain: np.ndarray, names: Sequence[str], sizes: Sequence[int],
                   log_prob: np.ndarray | None = None):
    """InferenceData from a chain (S, W, P): ``posterior`` has one variable per parameter with
    dims ``(chain=walker, draw=step[, <name>_dim_0=component])``."""
    az = arviz()
    walkers_first = np.swapaxes(chain, 0, 1)  # (W, S, P)
    posterior, offset = {}, 0
    for name, n in zip(names, sizes):
        block = walkers_first[..., offset:offset + n]
        posterior[name] = block[..., 0] if n == 1 else block
        offset += n
    stats = {"lp": np.swapaxes(log_prob, 0, 1)} if log_prob is not None else None
    with warnings.catch_warnings():  # "more chains than draws" for short chains: intended
        warnings.simplefilter("ignore", UserWarning)
        return az.from_dict(posterior=posterior, sample_stats=stats)


def write_netcdf(idata, path: str | Path) -> Path:
    """Write InferenceData to ``path`` (netCDF-4 via h5netcdf)."""
    path = Path(path)
    idata.to_netcdf(str(path), engine="h5netcdf")
    return path


def r_hat(idata, names: Sequence[str]) -> np.ndarray:
    """Rank-normalised split R-hat per scalar (walkers as chains), in ``names`` order."""
    values = arviz().rhat(idata)
    return np.concatenate([np.atleast_1d(np.asarray(values[n])) for n in names])
