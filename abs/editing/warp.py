"""The gradient warp ``t = x + s grad d'`` shared by re-texturing and transparency (Khan et al. 2006).

Each object pixel ``x`` looks up an image (a texture, or the background behind the object) at
``x + s (gx, gy)``, the depth map's reshaped gradient scaled by ``s``: a refraction-like
displacement that follows the shape, which human vision reads as the object's bulk. The paper
does not fix ``s``; since abs's gradients are slopes (pixels per pixel, see
:func:`abs.editing.depth.depth_from_luminance`), ``s`` is a length in pixels, and
:func:`default_strength` (our choice) makes it a quarter of the object's equivalent radius.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["equivalent_radius", "default_strength", "warp_coordinates", "sample"]


def equivalent_radius(mask: np.ndarray) -> float:
    """``sqrt(area / pi)`` of the object, pixels."""
    return float(np.sqrt(np.count_nonzero(mask) / np.pi))


def default_strength(mask: np.ndarray) -> float:
    """Our default ``s``: 0.25 times the object's equivalent radius, pixels."""
    return 0.25 * equivalent_radius(mask)


def warp_coordinates(gx: np.ndarray, gy: np.ndarray, strength: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``t = x + s grad d'`` of every pixel.

    Parameters
    ----------
    gx, gy : np.ndarray
        ``(height, width)`` depth gradients (slopes).
    strength : float
        ``s`` in pixels (may be negative: the displacement then points down the slope).

    Returns
    -------
    tx, ty : np.ndarray
        ``(height, width)`` float64 column and row coordinates (pixel centres at integers).
    """
    h, w = np.shape(gx)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return xs + strength * np.asarray(gx, np.float64), ys + strength * np.asarray(gy, np.float64)


def sample(image: np.ndarray, tx: np.ndarray, ty: np.ndarray, wrap: bool = False) -> np.ndarray:
    """Bilinear lookup of ``image`` at ``(tx, ty)`` (OpenCV ``remap``).

    Parameters
    ----------
    image : np.ndarray
        ``(H, W)`` or ``(H, W, C)`` image.
    tx, ty : np.ndarray
        Coordinates (column, row), any 2-D shape.
    wrap : bool
        Tile the image beyond its border (textures) instead of mirroring it (photographs).

    Returns
    -------
    np.ndarray
        float32, shape of ``tx`` (plus channels).
    """
    border = cv2.BORDER_WRAP if wrap else cv2.BORDER_REFLECT_101
    return cv2.remap(np.ascontiguousarray(image, np.float32), np.asarray(tx, np.float32),
                     np.asarray(ty, np.float32), interpolation=cv2.INTER_LINEAR, borderMode=border)
