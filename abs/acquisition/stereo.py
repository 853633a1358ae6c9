"""Stereo calibration of a camera pair (R, T, E, F) and the epipolar error of held-out pairs.

Each camera is first calibrated on its own (:func:`calibrate_intrinsics`); ``stereoCalibrate``
then finds the pose of camera 2 relative to camera 1 with the intrinsics fixed, so that a poor
stereo view cannot spoil K. ``x_cam2 = R @ x_cam1 + T`` (metres, board units).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["StereoCalibration", "calibrate_stereo", "epipolar_errors_px"]


@dataclass
class StereoCalibration:
    """Result of :func:`calibrate_stereo`.

    Attributes
    ----------
    R : np.ndarray
        (3, 3) rotation from camera-1 to camera-2 coordinates.
    T : np.ndarray
        (3,) translation, metres: ``x_cam2 = R @ x_cam1 + T``.
    E, F : np.ndarray
        (3, 3) essential and fundamental matrices; F relates *undistorted* pixels,
        ``[u2, v2, 1] F [u1, v1, 1]^T = 0``.
    rms_px : float
        RMS reprojection error of the stereo fit over the training pairs, pixels.
    pair_rms_px : np.ndarray
        (n_train, 2) RMS reprojection error per training pair and camera, pixels.
    """

    R: np.ndarray
    T: np.ndarray
    E: np.ndarray
    F: np.ndarray
    rms_px: float
    pair_rms_px: np.ndarray

    @property
    def baseline_m(self) -> float:
        """Distance between the camera centres, metres."""
        return float(np.linalg.norm(self.T))


def calibrate_stereo(points1: Sequence[np.ndarray], points2: Sequence[np.ndarray],
                     object_points: np.ndarray, K1: np.ndarray, dist1: np.ndarray,
                     K2: np.ndarray, dist2: np.ndarray, width: int,
                     height: int) -> StereoCalibration:
    """Pose of camera 2 relative to camera 1 from pairs where both see the board.

    Parameters
    ----------
    points1, points2 : sequence of np.ndarray
        Per pair, ``(N, 2)`` corners in camera 1 and camera 2, pixels, NaN where a camera did
        not see a corner (a partial ChArUco board); each pair is fitted with the corners both
        cameras saw, at least 4.
    object_points : np.ndarray
        ``(N, 3)`` board corners, metres.
    K1, dist1, K2, dist2 : np.ndarray
        Intrinsics of each camera (held fixed).
    width, height : int
        Image size, pixels.
    """
    if len(points1) != len(points2):
        raise InputError(None, "pairs", f"{len(points1)} left and {len(points2)} right views")
    if len(points1) < 1:
        raise InputError(None, "pairs", "no pair where both cameras see the board")
    obj, p1, p2 = [], [], []
    for k, (a, b) in enumerate(zip(points1, points2)):
        both = _seen_in_both(a, b)
        if both.sum() < 4:
            raise InputError(None, f"pairs[{k}]", f"{both.sum()} corners seen by both cameras; a "
                                                  "pair needs at least 4")
        obj.append(np.asarray(object_points, np.float32)[both].reshape(-1, 1, 3))
        p1.append(np.asarray(a, np.float32).reshape(-1, 2)[both].reshape(-1, 1, 2))
        p2.append(np.asarray(b, np.float32).reshape(-1, 2)[both].reshape(-1, 1, 2))
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    out = cv2.stereoCalibrateExtended(obj, p1, p2, np.asarray(K1, np.float64),
                                      np.asarray(dist1), np.asarray(K2, np.float64),
                                      np.asarray(dist2), (width, height), np.eye(3),
                                      np.zeros((3, 1)), flags=cv2.CALIB_FIX_INTRINSIC,
                                      criteria=criteria)
    rms, _, _, _, _, R, T, E, F, _, _, per_view = out
    return StereoCalibration(R=np.asarray(R, np.float64), T=np.ravel(T).astype(np.float64),
                             E=np.asarray(E, np.float64), F=np.asarray(F, np.float64),
                             rms_px=float(rms), pair_rms_px=np.asarray(per_view, np.float64))


def _seen_in_both(points1: np.ndarray, points2: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the corners with finite positions in both views."""
    a = np.asarray(points1, np.float64).reshape(-1, 2)
    b = np.asarray(points2, np.float64).reshape(-1, 2)
    return np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)


def epipolar_errors_px(points1: np.ndarray, points2: np.ndarray, F: np.ndarray,
                       K1: np.ndarray, dist1: np.ndarray, K2: np.ndarray,
                       dist2: np.ndarray) -> np.ndarray:
    """Symmetric distance of matched points to each other's epipolar lines, pixels.

    Points are undistorted first (F relates undistorted pixels); the result for each match is
    the mean of the distance of point 2 to the line of point 1 and vice versa. Corners that
    either view did not see (NaN) are left out.

    Returns
    -------
    np.ndarray
        ``(M,)`` distances of the M corners seen in both views, pixels.
    """
    both = _seen_in_both(points1, points2)
    p1 = np.asarray(points1, np.float64).reshape(-1, 2)[both]
    p2 = np.asarray(points2, np.float64).reshape(-1, 2)[both]
    u1 = cv2.undistortPoints(p1.reshape(-1, 1, 2), K1, dist1, P=K1)
    u2 = cv2.undistortPoints(p2.reshape(-1, 1, 2), K2, dist2, P=K2)
    u1, u2 = u1.reshape(-1, 2), u2.reshape(-1, 2)
    lines2 = cv2.computeCorrespondEpilines(u1.reshape(-1, 1, 2), 1, F).reshape(-1, 3)
    lines1 = cv2.computeCorrespondEpilines(u2.reshape(-1, 1, 2), 2, F).reshape(-1, 3)
    # computeCorrespondEpilines normalises lines so that a^2 + b^2 = 1: a dot product is a distance.
    d2 = np.abs(np.sum(lines2[:, :2] * u2, axis=1) + lines2[:, 2])
    d1 = np.abs(np.sum(lines1[:, :2] * u1, axis=1) + lines1[:, 2])
    return 0.5 * (d1 + d2)
