"""Placement: pair the markers measured in the scene with the CT marker centres, then the rigid
transform (rotation and translation, no reflection, no scale) that maps the CT object onto them.

Pairing matches pairwise-distance patterns: every triple of measured markers is tried against
every ordered triple of CT markers with the same three distances (within ``tol``); the
transform of each such triple (Kabsch) pairs every measured marker with the CT marker it lands
nearest, if within ``tol``; the pairing with most pairs, then the lowest RMS, wins. Two
different pairings that both explain the markers (a symmetric layout) are refused rather than
guessed; ``pairs`` overrides the automatic pairing.

Frames and units: CT centres in the object frame, measured markers in the world frame, both in
metres here; residuals are reported in mm. ``to_world`` maps object to world coordinates:
``X_world = R @ X_object + t``.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from abs.errors import InputError

__all__ = ["Placement", "kabsch", "match_markers", "place"]


@dataclass(frozen=True)
class Placement:
    """A fitted rigid placement.

    Attributes
    ----------
    R : np.ndarray
        ``(3, 3)`` rotation, object to world (``det = +1``).
    t : np.ndarray
        ``(3,)`` translation, metres.
    pairs : np.ndarray
        ``(n, 2)`` index pairs ``(measured, ct)``.
    residuals_mm : np.ndarray
        ``(n,)`` distance of each measured marker from its transformed CT marker, mm.
    """

    R: np.ndarray
    t: np.ndarray
    pairs: np.ndarray
    residuals_mm: np.ndarray

    @property
    def to_world(self) -> np.ndarray:
        """``(4, 4)`` object-to-world matrix (metres), as a scene file's ``to_world``."""
        m = np.eye(4)
        m[:3, :3] = self.R
        m[:3, 3] = self.t
        return m

    @property
    def mean_distance_mm(self) -> float:
        """Mean marker distance after the transform, mm (the seed reached 0.43 mm)."""
        return float(np.mean(self.residuals_mm))

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm ** 2)))


def kabsch(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation (no reflection) and translation with ``dst ~ R @ src + t``."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    H = (src - cs).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    return R, cd - R @ cs


def _pair_up(measured: np.ndarray, ct: np.ndarray, R: np.ndarray, t: np.ndarray,
             tol: float) -> tuple[tuple[tuple[int, int], ...], float]:
    moved = ct @ R.T + t
    d = np.linalg.norm(measured[:, None, :] - moved[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(np.where(d < tol, d, 1e6))
    ok = d[rows, cols] < tol
    pairs = tuple((int(r), int(c)) for r, c in zip(rows[ok], cols[ok]))
    rms = float(np.sqrt(np.mean(d[rows[ok], cols[ok]] ** 2))) if ok.any() else np.inf
    return pairs, rms


def match_markers(measured: np.ndarray, ct: np.ndarray, tol: float = 1.5e-3) -> np.ndarray:
    """Pair measured markers with CT markers by their pairwise distances.

    Parameters
    ----------
    measured : (n, 3) array
        Marker positions in the world, metres.
    ct : (m, 3) array
        CT marker centres in the object frame, metres.
    tol : float
        Accepted difference of a pair of distances, and of a paired marker after the
        transform, metres.

    Returns
    -------
    (k, 2) int array
        ``(measured index, ct index)`` pairs, ``k >= 3``.

    Raises
    ------
    InputError
        Fewer than 3 markers on either side, no consistent triple (fewer than 3 pairs), or two
        different pairings explaining the markers equally well.
    """
    measured = np.asarray(measured, dtype=np.float64).reshape(-1, 3)
    ct = np.asarray(ct, dtype=np.float64).reshape(-1, 3)
    if len(measured) < 3 or len(ct) < 3:
        raise InputError(None, "markers", f"placement needs at least 3 markers on each side; got "
                                          f"{len(measured)} measured and {len(ct)} in the CT")
    dm = np.linalg.norm(measured[:, None] - measured[None], axis=2)
    dc = np.linalg.norm(ct[:, None] - ct[None], axis=2)
    found: dict[tuple, float] = {}
    for i, j, k in itertools.combinations(range(len(measured)), 3):
        for p, q, r in itertools.permutations(range(len(ct)), 3):
            if (abs(dm[i, j] - dc[p, q]) > tol or abs(dm[j, k] - dc[q, r]) > tol
                    or abs(dm[i, k] - dc[p, r]) > tol):
                continue
            R, t = kabsch(ct[[p, q, r]], measured[[i, j, k]])
            pairs, rms = _pair_up(measured, ct, R, t, tol)
            if len(pairs) >= 3:
                # refit on all pairs and pair again, so the score is the pairing's own
                mi, ci = np.array(pairs).T
                R, t = kabsch(ct[ci], measured[mi])
                pairs, rms = _pair_up(measured, ct, R, t, tol)
                if len(pairs) >= 3:
                    found[pairs] = min(rms, found.get(pairs, np.inf))
    if not found:
        raise InputError(None, "markers", (
            f"fewer than 3 matched markers: no 3 of the {len(measured)} measured markers have the "
            f"pairwise distances of 3 of the {len(ct)} CT markers (within {tol * 1e3:g} mm); "
            "check the units (metres) or give the pairs by hand"))
    ranked = sorted(found.items(), key=lambda kv: (-len(kv[0]), kv[1]))
    best_pairs, best_rms = ranked[0]
    for pairs, rms in ranked[1:]:
        if len(pairs) == len(best_pairs) and rms < 2 * best_rms + 0.1 * tol:
            raise InputError(None, "markers", (
                f"ambiguous pairing: {_describe(best_pairs)} (RMS {best_rms * 1e3:.2f} mm) and "
                f"{_describe(pairs)} (RMS {rms * 1e3:.2f} mm) fit about equally; the marker "
                "layout is too symmetric, give the pairs by hand (--pairs)"))
        break
    return np.array(best_pairs, dtype=int)


def _describe(pairs) -> str:
    return ", ".join(f"{m}->{c}" for m, c in pairs)


def place(measured: np.ndarray, ct: np.ndarray, pairs: Sequence[tuple[int, int]] | None = None,
          tol: float = 1.5e-3, allow_unpaired: bool = False) -> Placement:
    """Pair (unless ``pairs`` is given) and solve the rigid transform (Kabsch).

    Parameters
    ----------
    measured : (n, 3) array
        Measured (triangulated) markers, world frame, metres.
    ct : (m, 3) array
        CT marker centres, object frame, metres.
    pairs : sequence of (measured index, ct index), optional
        A pairing given by hand; checked, not matched.
    tol : float
        Matching tolerance, metres (see :func:`match_markers`).
    allow_unpaired : bool
        Accept an automatic pairing that leaves measured markers unpaired. By default that is
        an error: every measured marker should be a CT marker, and a mirrored volume (slices in
        the opposite order) typically pairs only some of them.

    Raises
    ------
    InputError
        Fewer than 3 pairs, indices out of range or used twice, an automatic pairing that
        fails (see :func:`match_markers`) or that leaves measured markers unpaired.
    """
    measured = np.asarray(measured, dtype=np.float64).reshape(-1, 3)
    ct = np.asarray(ct, dtype=np.float64).reshape(-1, 3)
    if pairs is None:
        pairs = match_markers(measured, ct, tol)
        unpaired = sorted(set(range(len(measured))) - set(pairs[:, 0].tolist()))
        if unpaired and not allow_unpaired:
            raise InputError(None, "markers", (
                f"measured marker(s) {', '.join(map(str, unpaired))} match no CT marker within "
                f"{tol * 1e3:g} mm once the other {len(pairs)} are placed: a false detection, or "
                "a mirrored volume (slices stored in the opposite order); allow unpaired markers "
                "(--allow-unpaired) or give the pairs by hand"))
    else:
        pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
        if len(pairs) < 3:
            raise InputError(None, "pairs", f"placement needs at least 3 matched markers, got {len(pairs)}")
        if (pairs < 0).any() or (pairs[:, 0] >= len(measured)).any() or (pairs[:, 1] >= len(ct)).any():
            raise InputError(None, "pairs", f"index out of range: {len(measured)} measured and "
                                            f"{len(ct)} CT markers")
        if len(set(pairs[:, 0])) < len(pairs) or len(set(pairs[:, 1])) < len(pairs):
            raise InputError(None, "pairs", "a marker is paired twice")
    mi, ci = pairs[:, 0], pairs[:, 1]
    R, t = kabsch(ct[ci], measured[mi])
    residuals = np.linalg.norm(measured[mi] - (ct[ci] @ R.T + t), axis=1) * 1e3
    return Placement(R, t, pairs, residuals)
