"""Demosaicing of a Bayer mosaic (no camera colour processing: values stay linear).

Two methods (:data:`DEMOSAIC_METHODS`):

- ``bilinear`` (:func:`demosaic_bilinear`, the default): full resolution, interpolated.
- ``superpixel`` (:func:`demosaic_superpixel`): each 2x2 CFA cell becomes one RGB pixel (its
  red site, the mean of its two green sites, its blue site): no interpolation, so nothing is
  blurred, at half the width and height. The half-resolution camera is :func:`superpixel_K`.

Bilinear: each colour plane is the mosaic masked to that colour's sites, convolved with the bilinear
kernels (``[[0,1,0],[1,4,1],[0,1,0]] / 4`` for green, ``[[1,2,1],[2,4,2],[1,2,1]] / 4`` for red and
blue) through OpenCV's ``filter2D`` with reflected borders: the same filter as colour-demosaicing's
``demosaicing_CFA_Bayer_bilinear``, whose reference outputs it reproduces exactly.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["CFA_PATTERNS", "DEMOSAIC_METHODS", "cfa_masks", "demosaic", "demosaic_bilinear",
           "demosaic_superpixel", "superpixel_any", "superpixel_K", "superpixel_mask"]

#: Bayer patterns by the colours of the top-left 2x2 block, row-major.
CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
#: Demosaicing methods of ``abs capture build`` (build file key ``demosaic``); the first is the
#: default.
DEMOSAIC_METHODS = ("bilinear", "superpixel")
#: Full-resolution pixel coordinates -> superpixel coordinates (both with pixel centres at
#: integers): superpixel (i, j) is the 2x2 cell of full-resolution pixels 2i, 2i+1 (columns) and
#: 2j, 2j+1 (rows), whose centre is at full-resolution (2i + 0.5, 2j + 0.5); so
#: ``u_half = (u_full - 0.5) / 2`` and likewise for v.
SUPERPIXEL_FROM_FULL = np.array([[0.5, 0.0, -0.25], [0.0, 0.5, -0.25], [0.0, 0.0, 1.0]])
_GREEN_KERNEL = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]], np.float64) / 4.0
_RED_BLUE_KERNEL = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]], np.float64) / 4.0


def cfa_masks(shape: tuple[int, int], pattern: str) -> np.ndarray:
    """``(H, W, 3)`` boolean masks of the R, G, B sites of a Bayer ``pattern``."""
    pattern = _check_pattern(pattern)
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    site = (rows % 2) * 2 + (cols % 2)  # index into the 2x2 pattern string
    colour_of_site = np.array([pattern[i] for i in range(4)])[site]
    return np.stack([colour_of_site == c for c in "RGB"], axis=-1)


def _check_pattern(pattern: str) -> str:
    pattern = str(pattern).upper()
    if pattern not in CFA_PATTERNS:
        raise InputError(None, "cfa_pattern", f"{pattern!r} is not a Bayer pattern; expected "
                                              f"one of {', '.join(CFA_PATTERNS)}")
    return pattern


def _cells(array: np.ndarray, pattern: str) -> dict[str, list[np.ndarray]]:
    """The ``(H/2, W/2)`` planes of each colour's sites in the 2x2 cells, by colour."""
    array = np.asarray(array)
    if array.ndim != 2:
        raise InputError(None, "mosaic", f"expected a (height, width) mosaic, got shape "
                                         f"{array.shape}")
    h, w = array.shape
    if h % 2 or w % 2:
        raise InputError(None, "mosaic", f"the mosaic is {w}x{h} pixels; superpixel "
                                         "demosaicing needs an even width and height")
    pattern = _check_pattern(pattern)
    planes: dict[str, list[np.ndarray]] = {"R": [], "G": [], "B": []}
    for k, (dy, dx) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        planes[pattern[k]].append(array[dy::2, dx::2])
    return planes


def demosaic_superpixel(mosaic: np.ndarray, pattern: str, dtype=np.float32) -> np.ndarray:
    """Superpixel demosaicing: one RGB pixel per 2x2 CFA cell, no interpolation.

    Parameters
    ----------
    mosaic : np.ndarray
        ``(H, W)`` linear sensor values, H and W even.
    pattern : str
        Bayer pattern of the top-left 2x2 block: ``RGGB``, ``BGGR``, ``GRBG`` or ``GBRG``.
    dtype : numpy dtype
        Of the result (float64 for exact moments, :mod:`.blur`).

    Returns
    -------
    np.ndarray
        ``(H/2, W/2, 3)``: R and B the cell's red and blue sites, G the mean of its two
        green sites. Pixel (i, j) is centred on the cell's centre (:data:`SUPERPIXEL_FROM_FULL`);
        the red and blue sites themselves lie a quarter superpixel off it, diagonally.
    """
    planes = _cells(np.asarray(mosaic, np.float64), pattern)
    return np.stack([sum(planes[c]) / len(planes[c]) for c in "RGB"], axis=-1).astype(dtype)


def superpixel_any(flags: np.ndarray, pattern: str) -> np.ndarray:
    """``(H/2, W/2, 3)`` boolean: per superpixel and colour, whether any of the cell's sites of
    that colour is flagged (e.g. clipped) in the ``(H, W)`` boolean mosaic ``flags``."""
    planes = _cells(np.asarray(flags, bool), pattern)
    return np.stack([np.logical_or.reduce(planes[c]) for c in "RGB"], axis=-1)


def superpixel_mask(mask: np.ndarray) -> np.ndarray:
    """A full-resolution ``(H, W)`` comparison mask at superpixel resolution: a superpixel is
    kept only when all four pixels of its cell are (none of it comes from a masked-out area)."""
    m = np.asarray(mask, bool)
    if m.ndim != 2 or m.shape[0] % 2 or m.shape[1] % 2:
        raise InputError(None, "mask", f"expected an (H, W) mask with H and W even, got shape "
                                       f"{m.shape}")
    return m[0::2, 0::2] & m[0::2, 1::2] & m[1::2, 0::2] & m[1::2, 1::2]


def superpixel_K(K: np.ndarray) -> np.ndarray:
    """The camera matrix of a superpixel image, from the full-resolution ``K``.

    ``K_half = SUPERPIXEL_FROM_FULL @ K``: focal lengths (and skew) halved, principal point
    ``c_half = (c_full - 0.5) / 2`` (pixel centres at integers at both resolutions, a
    superpixel's centre at its 2x2 cell's centre). Lens distortion acts on normalised
    coordinates before K, so the distortion coefficients are unchanged: a point projecting to
    full-resolution ``(u, v)`` (with or without distortion) projects to
    ``((u - 0.5) / 2, (v - 0.5) / 2)``.
    """
    return SUPERPIXEL_FROM_FULL @ np.asarray(K, np.float64)


def demosaic_bilinear(mosaic: np.ndarray, pattern: str, dtype=np.float32) -> np.ndarray:
    """Bilinear demosaicing.

    Parameters
    ----------
    mosaic : np.ndarray
        ``(H, W)`` linear sensor values (any unit; dark-subtracted or not).
    pattern : str
        Bayer pattern of the top-left 2x2 block: ``RGGB``, ``BGGR``, ``GRBG`` or ``GBRG``.
    dtype : numpy dtype
        Of the result (float64 for exact moments, :mod:`.blur`).

    Returns
    -------
    np.ndarray
        ``(H, W, 3)`` R, G, B in the mosaic's unit.
    """
    mosaic = np.asarray(mosaic, np.float64)
    if mosaic.ndim != 2:
        raise InputError(None, "mosaic", f"expected a (height, width) mosaic, got shape "
                                         f"{mosaic.shape}")
    masks = cfa_masks(mosaic.shape, pattern)
    planes = [cv2.filter2D(mosaic * masks[..., c], -1, kernel, borderType=cv2.BORDER_REFLECT)
              for c, kernel in enumerate((_RED_BLUE_KERNEL, _GREEN_KERNEL, _RED_BLUE_KERNEL))]
    return np.stack(planes, axis=-1).astype(dtype)


def demosaic(mosaic: np.ndarray, pattern: str, method: str = DEMOSAIC_METHODS[0],
             dtype=np.float32) -> np.ndarray:
    """Demosaic ``mosaic`` by ``method`` (one of :data:`DEMOSAIC_METHODS`): the functions above
    by name."""
    methods = {"bilinear": demosaic_bilinear, "superpixel": demosaic_superpixel}
    if method not in methods:
        raise InputError(None, "demosaic", f"expected one of {', '.join(DEMOSAIC_METHODS)}, got "
                                           f"{method!r}")
    return methods[method](mosaic, pattern, dtype)
