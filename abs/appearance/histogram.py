"""Histogram matching, the baselines the paper shows to fail (issue 29).

Each channel of the image's object pixels is mapped, rank for rank, onto the target renderer's
characterisation histogram of log10 radiance: all object pixels at once onto the global histogram
(``global``), or each class's pixels onto that class's histogram (``local``). Neither knows θ
nor the scene: they move the distribution of values, not the look of a given pixel.
"""

from __future__ import annotations

import numpy as np

from abs.appearance.geometry import Geometry
from abs.appearance.statistics import HIST_EDGES, LOG_FLOOR, Characterisation

__all__ = ["match_global", "match_local"]


def _match(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``values (n,)`` mapped through their ranks onto the quantiles of histogram ``counts``."""
    if counts.sum() == 0 or values.size == 0:
        return values
    ranks = (np.argsort(np.argsort(np.log10(np.maximum(values, LOG_FLOOR)), kind="stable"),
                        kind="stable") + 0.5) / values.size
    cdf = np.concatenate([[0.0], np.cumsum(counts)]) / counts.sum()
    keep = np.concatenate([[True], np.diff(cdf) > 0])  # np.interp needs increasing abscissae
    return 10.0 ** np.interp(ranks, cdf[keep], HIST_EDGES[keep])


def match_global(image: np.ndarray, geometry: Geometry, target: Characterisation) -> np.ndarray:
    """All object pixels matched per channel to ``target``'s global histogram."""
    out = np.array(image, np.float64)
    mask = geometry.ids > 0
    for k in range(3):
        out[mask, k] = _match(out[mask, k], target.hist_global[k])
    return out.astype(np.float32)


def match_local(image: np.ndarray, geometry: Geometry, target: Characterisation) -> np.ndarray:
    """Each class's pixels matched per channel to ``target``'s histogram of that class."""
    out = np.array(image, np.float64)
    for cls in set(geometry.classes):
        c = target.class_index(cls)
        mask = geometry.class_mask(cls)
        if c is None or not mask.any():
            continue
        for k in range(3):
            out[mask, k] = _match(out[mask, k], target.hist_local[c, k])
    return out.astype(np.float32)
