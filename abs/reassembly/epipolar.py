"""Stereo matching of marker detections by their Sampson distance to the epipolar geometry.

The fundamental matrix comes from the calibration (two cameras of ``cameras.json``,
``x_cam = R @ X_world + t``, OpenCV, docs/conventions.md), not from the detections: markers are
few and alike, so no robust estimate from them could be trusted. A left and a right detection
match when their Sampson distance (the first-order distance, in pixels, of the pair from the
nearest pair that satisfies ``x2^T F x1 = 0``) is below a tolerance.

Markers are alike, so a left detection with two right detections near its epipolar line (or a
right one with two left ones) cannot be matched from the image pair alone. Such detections are
reported as ambiguous and left out, never matched by a guess.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["StereoMatches", "fundamental_matrix", "match_epipolar", "sampson_distance_px"]


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental_matrix(K1: np.ndarray, R1: np.ndarray, t1: np.ndarray, K2: np.ndarray,
                       R2: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """``F`` with ``[u2, v2, 1] F [u1, v1, 1]^T = 0`` for two calibrated cameras.

    Parameters
    ----------
    K1, R1, t1, K2, R2, t2 : np.ndarray
        Intrinsics (pixels) and world-to-camera poses (``t`` in metres) of camera 1 and 2.

    Returns
    -------
    np.ndarray
        ``(3, 3)``, scaled to unit Frobenius norm.
    """
    K1, R1, K2, R2 = (np.asarray(a, np.float64) for a in (K1, R1, K2, R2))
    t1, t2 = (np.asarray(a, np.float64).reshape(3) for a in (t1, t2))
    R = R2 @ R1.T  # camera 1 -> camera 2
    t = t2 - R @ t1
    E = _skew(t) @ R
    F = np.linalg.inv(K2).T @ E @ np.linalg.inv(K1)
    return F / np.linalg.norm(F)


def sampson_distance_px(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Sampson distance of every pair of points, pixels.

    Parameters
    ----------
    F : (3, 3) array
        Fundamental matrix, ``x2^T F x1 = 0``.
    x1, x2 : (n1, 2) and (n2, 2) arrays
        Pixel coordinates in image 1 and image 2.

    Returns
    -------
    (n1, n2) array
        ``|x2^T F x1| / sqrt((F x1)_1^2 + (F x1)_2^2 + (F^T x2)_1^2 + (F^T x2)_2^2)``.
    """
    h1 = np.column_stack([np.asarray(x1, np.float64).reshape(-1, 2), np.ones(len(x1))])
    h2 = np.column_stack([np.asarray(x2, np.float64).reshape(-1, 2), np.ones(len(x2))])
    Fx1 = h1 @ F.T  # epipolar lines in image 2
    Ftx2 = h2 @ F  # epipolar lines in image 1
    algebraic = Fx1 @ h2.T
    norm = (Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2)[:, None] + (Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)[None, :]
    return np.abs(algebraic) / np.sqrt(norm)


@dataclass(frozen=True)
class StereoMatches:
    """Result of :func:`match_epipolar`.

    Attributes
    ----------
    pairs : np.ndarray
        ``(k, 2)`` index pairs ``(left, right)`` matched without doubt.
    distances_px : np.ndarray
        ``(k,)`` Sampson distance of each pair, pixels.
    ambiguous : tuple of dict
        One entry per left detection with several right candidates, ``{"left": i, "right":
        [j, ...]}``, and per right detection with several left candidates, ``{"right": j,
        "left": [i, ...]}``; none of these detections is in ``pairs``.
    """

    pairs: np.ndarray
    distances_px: np.ndarray
    ambiguous: tuple[dict, ...]


def match_epipolar(x1: np.ndarray, x2: np.ndarray, F: np.ndarray, tol_px: float = 1.5) -> StereoMatches:
    """Match detections of two images whose Sampson distance is below ``tol_px``.

    A pair is kept only when each of its detections has exactly one candidate in the other
    image; detections with two or more are reported in ``ambiguous`` and left out.

    Parameters
    ----------
    x1, x2 : (n1, 2) and (n2, 2) arrays
        Detections (centres) in the left and right image, pixels.
    F : (3, 3) array
        Fundamental matrix from the calibration (:func:`fundamental_matrix`).
    tol_px : float
        Largest Sampson distance of a match, pixels.
    """
    x1 = np.asarray(x1, np.float64).reshape(-1, 2)
    x2 = np.asarray(x2, np.float64).reshape(-1, 2)
    if len(x1) == 0 or len(x2) == 0:
        return StereoMatches(np.zeros((0, 2), int), np.zeros(0), ())
    d = sampson_distance_px(F, x1, x2)
    close = d < tol_px
    per_left, per_right = close.sum(axis=1), close.sum(axis=0)
    ambiguous = [{"left": int(i), "right": np.flatnonzero(close[i]).tolist()}
                 for i in np.flatnonzero(per_left >= 2)]
    ambiguous += [{"right": int(j), "left": np.flatnonzero(close[:, j]).tolist()}
                  for j in np.flatnonzero(per_right >= 2)]
    sure = close & (per_left == 1)[:, None] & (per_right == 1)[None, :]
    i, j = np.nonzero(sure)
    return StereoMatches(np.column_stack([i, j]).astype(int), d[i, j], tuple(ambiguous))
