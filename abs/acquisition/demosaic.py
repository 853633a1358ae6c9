"""Bilinear demosaicing of a Bayer mosaic (no camera colour processing: values stay linear).

Each colour plane is the mosaic masked to that colour's sites, convolved with the bilinear
kernels (``[[0,1,0],[1,4,1],[0,1,0]] / 4`` for green, ``[[1,2,1],[2,4,2],[1,2,1]] / 4`` for red and
blue) through OpenCV's ``filter2D`` with reflected borders: the same filter as colour-demosaicing's
``demosaicing_CFA_Bayer_bilinear``, whose reference outputs it reproduces exactly.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["CFA_PATTERNS", "cfa_masks", "demosaic_bilinear"]

#: Bayer patterns by the colours of the top-left 2x2 block, row-major.
CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
_GREEN_KERNEL = np.array([[0, 1, 0], [1, 4, 1], [0, 1, 0]], np.float64) / 4.0
_RED_BLUE_KERNEL = np.array([[1, 2, 1], [2, 4, 2], [1, 2, 1]], np.float64) / 4.0


def cfa_masks(shape: tuple[int, int], pattern: str) -> np.ndarray:
    """``(H, W, 3)`` boolean masks of the R, G, B sites of a Bayer ``pattern``."""
    pattern = pattern.upper()
    if pattern not in CFA_PATTERNS:
        raise InputError(None, "cfa_pattern", f"{pattern!r} is not a Bayer pattern; expected "
                                              f"one of {', '.join(CFA_PATTERNS)}")
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    site = (rows % 2) * 2 + (cols % 2)  # index into the 2x2 pattern string
    colour_of_site = np.array([pattern[i] for i in range(4)])[site]
    return np.stack([colour_of_site == c for c in "RGB"], axis=-1)


def demosaic_bilinear(mosaic: np.ndarray, pattern: str) -> np.ndarray:
    """Bilinear demosaicing.

    Parameters
    ----------
    mosaic : np.ndarray
        ``(H, W)`` linear sensor values (any unit; dark-subtracted or not).
    pattern : str
        Bayer pattern of the top-left 2x2 block: ``RGGB``, ``BGGR``, ``GRBG`` or ``GBRG``.

    Returns
    -------
    np.ndarray
        ``(H, W, 3)`` float32 R, G, B in the mosaic's unit.
    """
    mosaic = np.asarray(mosaic, np.float64)
    if mosaic.ndim != 2:
        raise InputError(None, "mosaic", f"expected a (height, width) mosaic, got shape "
                                         f"{mosaic.shape}")
    masks = cfa_masks(mosaic.shape, pattern)
    planes = [cv2.filter2D(mosaic * masks[..., c], -1, kernel, borderType=cv2.BORDER_REFLECT)
              for c, kernel in enumerate((_RED_BLUE_KERNEL, _GREEN_KERNEL, _RED_BLUE_KERNEL))]
    return np.stack(planes, axis=-1).astype(np.float32)
