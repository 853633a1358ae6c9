"""Extrinsics from a board placed in the scene: the board defines the world axes.

World origin at the board's first inner corner, x along its rows of corners, y along its columns,
z = x cross y (into the board for a board seen from the front), metres. ``solvePnP`` on the
detected corners with the camera's calibrated K and distortion gives ``x_cam = R X + t``.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.acquisition.board import seen_points
from abs.errors import InputError

__all__ = ["board_pose"]


def board_pose(corners: np.ndarray, object_points: np.ndarray, K: np.ndarray,
               dist: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """World-to-camera pose from one view of the board.

    Parameters
    ----------
    corners : np.ndarray
        ``(N, 2)`` detected corners, pixels; NaN rows (corners not seen) are left out.
    object_points : np.ndarray
        ``(N, 3)`` the same corners on the board (world), metres.
    K, dist : np.ndarray
        The camera's intrinsics.

    Returns
    -------
    R : np.ndarray
        (3, 3) rotation, world to camera.
    t : np.ndarray
        (3,) translation, metres.
    rms_px : float
        RMS reprojection error of the pose, pixels.
    """
    _, img, obj = seen_points(np.asarray(corners, np.float64),
                              np.asarray(object_points, np.float64))
    if len(img) < 4:
        raise InputError(None, "corners", f"{len(img)} corners seen; a pose needs at least 4")
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise InputError(None, "corners", "solvePnP found no pose for the board")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - img) ** 2, axis=1))))
    return cv2.Rodrigues(rvec)[0], np.ravel(tvec), rms
