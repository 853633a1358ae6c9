"""The ColorChecker Classic chart: reference values and patch colours from a photograph.

Patches are numbered 1-24 row by row as printed (1 dark skin ... 6 bluish green, 19 white ...
24 black), 4 rows of 6. A photograph's patch colours are taken either

- from **corner points**: the image positions (pixels, conventions.md) of the centres of the
  four corner patches 1, 6, 24, 19 (clockwise from dark skin). A homography (OpenCV) maps the
  chart's patch grid into the image, and each patch is the mean of a square window around its
  centre, a fraction of the patch pitch wide (so the black gaps are never sampled);
- or from a **label mask**: an image whose pixel value is the patch number (0 elsewhere).

Either way the user can correct what an automatic detector found by editing the points or the
mask. Reference XYZ are colour-science's published ColorChecker24 values (D50, white Y ~ 0.9).
"""

from __future__ import annotations

from pathlib import Path

import colour
import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["PATCHES", "REFERENCE_CHART", "reference_xyz", "reference_white_xyz", "patch_centres",
           "patch_rgb_from_corners", "patch_rgb_from_labels", "check_patches"]

#: Number of patches of a ColorChecker Classic (4 rows x 6 columns).
PATCHES = 24
_ROWS, _COLS = 4, 6

#: colour-science's name of the default reference chart.
REFERENCE_CHART = "ColorChecker24 - After November 2014"


def reference_xyz(chart: str = REFERENCE_CHART) -> np.ndarray:
    """Published XYZ of the 24 patches, shape (24, 3), under the chart's illuminant (D50)."""
    data = colour.CCS_COLOURCHECKERS[chart]
    return np.asarray(colour.xyY_to_XYZ(np.array(list(data.data.values()))), np.float64)


def reference_white_xyz(chart: str = REFERENCE_CHART) -> np.ndarray:
    """XYZ of the perfect white diffuser (Y = 1) under the chart's illuminant, shape (3,)."""
    return np.asarray(colour.xy_to_XYZ(colour.CCS_COLOURCHECKERS[chart].illuminant), np.float64)


def patch_centres(corners_px: np.ndarray) -> np.ndarray:
    """Image positions of the 24 patch centres from the centres of patches 1, 6, 24, 19.

    Parameters
    ----------
    corners_px : ndarray, shape (4, 2)
        ``(u, v)`` pixels of the centres of patches 1, 6, 24 and 19, in that order.

    Returns
    -------
    ndarray, shape (24, 2)
        ``(u, v)`` of patches 1..24.
    """
    grid = np.array([[0, 0], [_COLS - 1, 0], [_COLS - 1, _ROWS - 1], [0, _ROWS - 1]], np.float32)
    h = cv2.getPerspectiveTransform(grid, np.asarray(corners_px, np.float32).reshape(4, 2))
    cols, rows = np.meshgrid(np.arange(_COLS), np.arange(_ROWS))
    pts = np.stack([cols.ravel(), rows.ravel()], -1).astype(np.float32)[None]
    return cv2.perspectiveTransform(pts, h)[0].astype(np.float64)


def patch_rgb_from_corners(image: np.ndarray, corners_px: np.ndarray, window: float = 0.4,
                           source: str | None = None) -> np.ndarray:
    """Mean linear RGB of each patch in a square window around its centre.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        Linear camera RGB.
    corners_px : ndarray, shape (4, 2)
        See :func:`patch_centres`.
    window : float
        Window side as a fraction of the local patch pitch (0.4 stays well inside a patch).
    source : str, optional
        Name of the image file, for errors.

    Returns
    -------
    ndarray, shape (24, 3)
        NaN rows for patches whose window falls outside the image (see :func:`check_patches`).
    """
    centres = patch_centres(corners_px)
    grid = centres.reshape(_ROWS, _COLS, 2)
    pitch = 0.5 * (np.linalg.norm(np.diff(grid, axis=1), axis=-1).mean()
                   + np.linalg.norm(np.diff(grid, axis=0), axis=-1).mean())
    half = max(1, int(round(window * pitch / 2)))
    h, w = image.shape[:2]
    out = np.full((PATCHES, 3), np.nan)
    for i, (u, v) in enumerate(np.round(centres).astype(int)):
        if half <= u < w - half and half <= v < h - half:
            out[i] = image[v - half:v + half + 1, u - half:u + half + 1].reshape(-1, 3).mean(0)
    return out


def patch_rgb_from_labels(image: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Mean linear RGB of the pixels labelled 1..24; NaN rows for labels absent from the mask."""
    out = np.full((PATCHES, 3), np.nan)
    for i in range(PATCHES):
        sel = labels == i + 1
        if sel.any():
            out[i] = image[sel].mean(0)
    return out


def check_patches(rgb: np.ndarray, source: str | Path | None, field: str = "patches") -> np.ndarray:
    """Refuse a patch table with missing (NaN), non-positive or wrongly shaped entries.

    Raises
    ------
    InputError
        Naming ``source`` and ``field`` and listing the missing patch numbers (1-based).
    """
    arr = np.asarray(rgb, np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(source, field, f"expected rows of 3 numbers (R, G, B), got shape {arr.shape}")
    if arr.shape[0] != PATCHES:
        raise InputError(source, field, f"expected {PATCHES} patches, got {arr.shape[0]}")
    missing = [i + 1 for i in range(PATCHES) if not np.all(np.isfinite(arr[i]))]
    if missing:
        raise InputError(source, field, f"missing patches {missing} (outside the image or not "
                                        "in the mask)")
    dark = [i + 1 for i in range(PATCHES) if np.any(arr[i] <= 0)]
    if dark:
        raise InputError(source, field, f"patches {dark} have a zero or negative channel "
                                        "(under-exposed or not linear)")
    return arr
