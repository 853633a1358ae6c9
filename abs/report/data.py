"""Reading ``fit.json``'s summary and the iteration history into arrays, tolerating gaps.

Optional values (``truth``, ``stderr``, a missing iteration record) come out as NaN so that the
figures and tables can show "not given" without a branch per key.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["as_vector", "loss_curve", "parameter_traces"]


def as_vector(value: object) -> np.ndarray:
    """A scalar, list or ``None`` as a 1-d ``float64`` array; ``None`` entries become NaN."""
    if value is None:
        value = np.nan
    elif isinstance(value, (list, tuple)):
        value = [np.nan if v is None else v for v in value]
    return np.atleast_1d(np.asarray(value, dtype=np.float64))


def loss_curve(history: Sequence[Mapping]) -> tuple[np.ndarray, np.ndarray]:
    """Iterations and their loss, skipping records without one.

    Parameters
    ----------
    history : sequence of dict
        Per-iteration records with ``iteration`` and ``loss``.

    Returns
    -------
    (np.ndarray, np.ndarray)
        Iteration numbers and losses, both of shape ``(n,)``.
    """
    records = [h for h in history if h.get("loss") is not None]
    return (np.array([h["iteration"] for h in records]),
            np.array([h["loss"] for h in records], dtype=np.float64))


def parameter_traces(history: Sequence[Mapping],
                     names: Sequence[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each parameter's values over the iterations that recorded it.

    Parameters
    ----------
    history : sequence of dict
        Per-iteration records with ``iteration`` and ``values`` (parameter name → value).
    names : sequence of str
        Parameters to list first, in this order (``fit.json``'s); parameters only in
        ``history`` follow in alphabetical order.

    Returns
    -------
    dict
        Name → ``(iterations, values)``: arrays of shape ``(n,)`` and ``(n, components)``.
        Parameters never recorded are left out.
    """
    recorded = {n for h in history for n in h.get("values", {})}
    order = [n for n in names if n in recorded] + sorted(recorded - set(names))
    traces = {}
    for name in order:
        records = [h for h in history if name in h.get("values", {})]
        traces[name] = (np.array([h["iteration"] for h in records]),
                        np.stack([as_vector(h["values"][name]) for h in records]))
    return traces
