"""Intrinsic calibration (K and distortion) from many views of a board, with diagnostics.

OpenCV's ``calibrateCameraExtended`` does the fit (Brown-Conrady distortion, coefficients
``k1, k2, p1, p2, k3`` in OpenCV's order) and gives the parameters' standard deviations. Here we
add the checks a user needs: RMS reprojection error per view, outlier views with the reason, and
how much of the image the board covered (views that never reach the image corners leave the
distortion there unconstrained).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from abs.acquisition.board import seen_points
from abs.errors import InputError

__all__ = ["IntrinsicCalibration", "calibrate_intrinsics", "coverage_map", "OUTLIER_FACTOR",
           "POOR_COVERAGE", "MIN_VIEW_CORNERS"]

#: A view whose RMS reprojection error exceeds this many times the median view's is an outlier.
OUTLIER_FACTOR = 3.0
#: Coverage (fraction of image pixels inside at least one board outline) below this is poor.
POOR_COVERAGE = 0.5
#: Names of ``calibrateCameraExtended``'s intrinsic standard deviations, in its order.
_PARAMETER_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


@dataclass
class IntrinsicCalibration:
    """Result of :func:`calibrate_intrinsics`.

    Attributes
    ----------
    K : np.ndarray
        (3, 3) camera matrix, pixels (pixel centres at integers).
    dist : np.ndarray
        (5,) distortion ``k1, k2, p1, p2, k3`` (OpenCV order, dimensionless).
    width, height : int
        Image size, pixels.
    rms_px : float
        Overall RMS reprojection error, pixels.
    view_rms_px : np.ndarray
        (n_views,) RMS reprojection error per view, pixels.
    std : dict of str to float
        Standard deviation of each intrinsic parameter (``fx`` ... ``k3``), its own units.
    rvecs, tvecs : np.ndarray
        (n_views, 3) board-to-camera rotation vectors (rad) and translations (metres).
    names : list of str
        View names, in order.
    outliers : dict of str to str
        Outlier view name -> reason.
    coverage : float
        Fraction of image pixels inside at least one detected board outline.
    """

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    rms_px: float
    view_rms_px: np.ndarray
    std: dict[str, float]
    rvecs: np.ndarray
    tvecs: np.ndarray
    names: list[str]
    outliers: dict[str, str] = field(default_factory=dict)
    coverage: float = 0.0

    @property
    def poor_coverage(self) -> bool:
        """True when the boards covered less than :data:`POOR_COVERAGE` of the image."""
        return self.coverage < POOR_COVERAGE


def coverage_map(image_points: Sequence[np.ndarray], width: int, height: int) -> np.ndarray:
    """How many views' board outlines (convex hulls of the corners seen) cover each pixel.

    Returns
    -------
    np.ndarray
        ``(height, width)`` int32 counts; ``(counts > 0).mean()`` is the coverage fraction.
    """
    counts = np.zeros((height, width), np.int32)
    for pts in image_points:
        pts = np.asarray(pts, np.float32).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]  # corners a partial view did not show
        if len(pts) < 3:
            continue
        hull = cv2.convexHull(np.round(pts).astype(np.int32))
        one = np.zeros((height, width), np.uint8)
        cv2.fillConvexPoly(one, hull, 1)
        counts += one
    return counts


#: Fewest corners a view must show: OpenCV starts each view from a homography (4 points).
MIN_VIEW_CORNERS = 4


def _check_views(image_points: Sequence[np.ndarray], names: Sequence[str]) -> None:
    if len(image_points) != len(names):
        raise InputError(None, "names", f"{len(names)} names for {len(image_points)} views")
    if len(image_points) < 3:
        raise InputError(None, "images", f"the board was found in {len(image_points)} image(s); "
                                         "intrinsic calibration needs at least 3 varied views")


def _view_points(image_points: Sequence[np.ndarray], object_points: np.ndarray,
                 names: Sequence[str]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per view, the corners it shows and their board points (float32, OpenCV's shapes)."""
    obj, img = [], []
    for name, points in zip(names, image_points):
        _, seen, board = seen_points(points, object_points)
        if len(seen) < MIN_VIEW_CORNERS:
            raise InputError(None, name, f"{len(seen)} corners seen; a view needs at least "
                                         f"{MIN_VIEW_CORNERS}")
        obj.append(np.asarray(board, np.float32).reshape(-1, 1, 3))
        img.append(np.asarray(seen, np.float32).reshape(-1, 1, 2))
    return obj, img


def calibrate_intrinsics(image_points: Sequence[np.ndarray], object_points: np.ndarray,
                         width: int, height: int, names: Sequence[str] | None = None,
                         flags: int = 0) -> IntrinsicCalibration:
    """Calibrate K and distortion from board corners seen in several views.

    Parameters
    ----------
    image_points : sequence of np.ndarray
        Per view, ``(N, 2)`` detected corners, pixels, in ``object_points`` order; NaN rows for
        corners the view does not show (a partial ChArUco board): each view is fitted with the
        corners it shows, at least :data:`MIN_VIEW_CORNERS`.
    object_points : np.ndarray
        ``(N, 3)`` corner positions on the board, metres (:meth:`Board.object_points`).
    width, height : int
        Image size, pixels (all views alike).
    names : sequence of str, optional
        View names for the report (default ``view0``, ``view1``, ...).
    flags : int
        Extra OpenCV ``CALIB_*`` flags.

    Returns
    -------
    IntrinsicCalibration
    """
    names = list(names) if names is not None else [f"view{i}" for i in range(len(image_points))]
    _check_views(image_points, names)
    obj, img = _view_points(image_points, object_points, names)
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, rvecs, tvecs, std_in, _, per_view = cv2.calibrateCameraExtended(
        obj, img, (width, height), None, None, flags=flags, criteria=criteria)
    view_rms = np.asarray(per_view, np.float64).ravel()
    std = {n: float(s) for n, s in zip(_PARAMETER_NAMES, np.ravel(std_in))}
    median = float(np.median(view_rms))
    outliers = {n: (f"RMS reprojection error {e:.3f} px is more than {OUTLIER_FACTOR:g} x the "
                    f"median view's {median:.3f} px (blur, a mis-detected corner or a moved "
                    "board)")
                for n, e in zip(names, view_rms) if e > OUTLIER_FACTOR * median}
    coverage = float((coverage_map(image_points, width, height) > 0).mean())
    return IntrinsicCalibration(
        K=np.asarray(K, np.float64), dist=np.ravel(dist).astype(np.float64)[:5],
        width=int(width), height=int(height), rms_px=float(rms), view_rms_px=view_rms, std=std,
        rvecs=np.asarray(rvecs, np.float64).reshape(-1, 3),
        tvecs=np.asarray(tvecs, np.float64).reshape(-1, 3), names=names, outliers=outliers,
        coverage=coverage)
