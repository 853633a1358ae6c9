"""Suspect markers after placement: a measured marker that the other markers' placement puts far
from its CT marker (docs/reassembly.md).

A marker glued on glass is seen again, refracted, right beside itself; where the two images merge
into one blob, the detected centre is pulled by several pixels and the triangulated marker lands
a millimetre or more off, with nothing wrong in its detection or its reprojection error. Rigid
placement then shows it: with the marker left out, the others fix the transform, and its
distance from its transformed CT marker (the leave-one-out residual) stands out from the rest's.
The plain residual is a weaker test: the fit with the marker in bends towards it (six degrees of
freedom fitted to five or six markers).
"""

from __future__ import annotations

import numpy as np

from abs.reassembly.placement import kabsch

__all__ = ["leave_one_out_mm", "suspect_pairs"]


def leave_one_out_mm(measured: np.ndarray, ct: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Each pair's distance when the transform is fitted to the other pairs.

    Parameters
    ----------
    measured : (n, 3) array
        Measured markers, world frame, metres.
    ct : (m, 3) array
        CT marker centres, object frame, metres.
    pairs : (k, 2) int array
        ``(measured index, ct index)``.

    Returns
    -------
    (k,) float64
        Millimetres; all NaN with fewer than 4 pairs (3 others are needed to fix a rotation).
    """
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    out = np.full(len(pairs), np.nan)
    if len(pairs) < 4:
        return out
    src, dst = np.asarray(ct)[pairs[:, 1]], np.asarray(measured)[pairs[:, 0]]
    for i in range(len(pairs)):
        others = np.arange(len(pairs)) != i
        R, t = kabsch(src[others], dst[others])
        out[i] = np.linalg.norm(dst[i] - (R @ src[i] + t)) * 1e3
    return out


def suspect_pairs(measured: np.ndarray, ct: np.ndarray, pairs: np.ndarray, factor: float = 3.0,
                  floor_mm: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Which pairs stand out, one at a time.

    The pair with the largest leave-one-out residual is suspect when that residual is above
    ``factor`` times the median of the others' and above ``floor_mm``; it is then set aside and
    the rest tested again, while 4 pairs or more remain. One at a time because a bad marker in
    the fit moves the transform, so that the marker left out beside it looks bad too (measured:
    with a marker 1.2 mm off, a good one's leave-one-out residual reached 1.08 mm).

    Parameters
    ----------
    measured, ct, pairs
        As :func:`leave_one_out_mm`.
    factor : float
        How far above the others' median, as a ratio.
    floor_mm : float
        Residuals below this are never suspect, mm (the seed's placement reached 0.43 mm on
        average, so a marker within 0.5 mm is as good as a placement gets).

    Returns
    -------
    suspect : (k,) bool
    loo_mm : (k,) float64
        Each pair's leave-one-out residual (mm) among the pairs left when it was tested: the
        suspects' from the round that flagged them, the others' from the last round.
    """
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    suspect = np.zeros(len(pairs), dtype=bool)
    loo_all = np.full(len(pairs), np.nan)
    while np.count_nonzero(~suspect) >= 4:
        keep = np.flatnonzero(~suspect)
        loo = leave_one_out_mm(measured, ct, pairs[keep])
        loo_all[keep] = loo
        worst = int(np.argmax(loo))
        if loo[worst] <= max(factor * float(np.median(np.delete(loo, worst))), floor_mm):
            break
        suspect[keep[worst]] = True
    return suspect, loo_all
