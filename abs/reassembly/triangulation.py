"""Triangulated markers: matched detections to 3-D points, then one point per marker.

Each matched pair is triangulated linearly (``cv2.triangulatePoints``) and scored by its
reprojection error, the larger of its distances from the two detections (pixels). Points of one
marker seen in several camera pairs, or detected twice, are clustered (single linkage within
``merge_m``); within a cluster, points further than ``outlier_m`` from the cluster's median are
dropped, and of the rest the point with the lowest reprojection error is kept.

Units: metres for points, pixels for image coordinates and errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage

from abs.camera.pinhole import project

__all__ = ["MarkerCluster", "cluster_points", "projection_matrix", "triangulate"]


def projection_matrix(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(3, 4)`` matrix ``K [R | t]`` of a world-to-camera pose (OpenCV convention)."""
    return np.asarray(K, np.float64) @ np.column_stack([np.asarray(R, np.float64),
                                                        np.asarray(t, np.float64).reshape(3)])


def triangulate(cam1: tuple, cam2: tuple, x1: np.ndarray,
                x2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangulate matched pixels of two cameras.

    Parameters
    ----------
    cam1, cam2 : (K, R, t)
        The two cameras (pixels; world-to-camera rotation; metres).
    x1, x2 : (n, 2) arrays
        Matched pixel coordinates.

    Returns
    -------
    points : (n, 3) array
        World points, metres.
    error_px : (n,) array
        Reprojection error, the larger of the two views', pixels (inf for a point behind
        either camera).
    in_front : (n,) bool array
        The point lies in front of both cameras.
    """
    x1 = np.asarray(x1, np.float64).reshape(-1, 2)
    x2 = np.asarray(x2, np.float64).reshape(-1, 2)
    if len(x1) == 0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool)
    h = cv2.triangulatePoints(projection_matrix(*cam1), projection_matrix(*cam2), x1.T, x2.T)
    points = (h[:3] / h[3]).T
    e1 = np.linalg.norm(project(*cam1, points) - x1, axis=1)
    e2 = np.linalg.norm(project(*cam2, points) - x2, axis=1)
    in_front = np.isfinite(e1) & np.isfinite(e2)  # project gives NaN behind a camera
    error = np.where(in_front, np.maximum(e1, e2), np.inf)
    return points, error, in_front


@dataclass(frozen=True)
class MarkerCluster:
    """The points of one marker.

    Attributes
    ----------
    index : int
        Index (into the points clustered) of the kept point: the lowest reprojection error
        among the inliers.
    point : np.ndarray
        ``(3,)`` the kept point, metres.
    error_px : float
        Its reprojection error, pixels.
    members : np.ndarray
        Indices (into the points clustered) of the cluster's points.
    outliers : np.ndarray
        Indices of the members dropped for lying further than ``outlier_m`` from the median.
    """

    index: int
    point: np.ndarray
    error_px: float
    members: np.ndarray
    outliers: np.ndarray


def cluster_points(points: np.ndarray, error_px: np.ndarray, *, merge_m: float = 1e-3,
                   outlier_m: float = 0.5e-3) -> list[MarkerCluster]:
    """One point per marker from triangulated points.

    Parameters
    ----------
    points : (n, 3) array
        Triangulated points, metres.
    error_px : (n,) array
        Their reprojection errors, pixels.
    merge_m : float
        Points closer than this (single linkage) belong to one marker, metres. Markers of radius
        ``r`` that do not overlap lie at least ``2 r`` apart, so ``merge_m`` below ``2 r``
        never merges two markers.
    outlier_m : float
        A member further than this from its cluster's median is dropped, metres.

    Returns
    -------
    list of MarkerCluster
        Ordered by their first member.
    """
    points = np.asarray(points, np.float64).reshape(-1, 3)
    error_px = np.asarray(error_px, np.float64).reshape(-1)
    if len(points) == 0:
        return []
    labels = (fcluster(linkage(points, "single"), merge_m, criterion="distance")
              if len(points) > 1 else np.ones(1, int))
    out = []
    for label in dict.fromkeys(labels):  # first-seen order
        members = np.flatnonzero(labels == label)
        centre = np.median(points[members], axis=0)
        far = np.linalg.norm(points[members] - centre, axis=1) > outlier_m
        inliers = members[~far] if (~far).any() else members
        best = inliers[np.argmin(error_px[inliers])]
        out.append(MarkerCluster(int(best), points[best].copy(), float(error_px[best]), members,
                                 members[far]))
    return out
