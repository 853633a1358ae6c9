"""Re-texturing through the gradient warp and the matting equation (Khan et al. 2006, sec. 5).

    C'(x) = (1 - f) G(x) T(t(x)) + f C(x),      t = x + s grad d'

``T`` is the new texture (reflectance-like, linear RGB), ``t`` the warped texture coordinate
(:mod:`abs.editing.warp`), ``G`` the object's shading and ``f`` how much of the original shows
through. Our reading of the symbols the text we had leaves open:

- ``G`` is the photograph's luminance capped at the highlight threshold, ``min(L, t_h)``: the
  shading without the highlights, which are added back on top
  (:func:`abs.editing.highlights.highlight_layer`), as for every edit that replaces the surface;
- ``f`` (default 0.1, our choice) blends the original *without* its highlights, so they are not
  counted twice;
- the texture is scaled, keeping its aspect ratio, so that its longer side spans the longer side of
  the object's bounding box, and tiles beyond it.
"""

from __future__ import annotations

import numpy as np

from abs.colour.srgb import luminance
from abs.editing.highlights import highlight_layer
from abs.editing.warp import sample

__all__ = ["texture_coordinates", "retexture"]


def texture_coordinates(mask: np.ndarray, tx: np.ndarray, ty: np.ndarray,
                        texture_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Texture pixel coordinates of warped image coordinates ``(tx, ty)``.

    Parameters
    ----------
    mask : np.ndarray of bool
        The object's pixels (its bounding box sets the texture's placement).
    tx, ty : np.ndarray
        Warped image coordinates (:func:`abs.editing.warp.warp_coordinates`).
    texture_shape : (int, int)
        ``(height, width)`` of the texture.

    Returns
    -------
    u, v : np.ndarray
        Texture column and row coordinates (pixel centres at integers).
    """
    rows, cols = np.nonzero(mask)
    y0, x0 = rows.min(), cols.min()
    span = max(rows.max() - y0 + 1, cols.max() - x0 + 1)
    scale = max(texture_shape) / span
    return (np.asarray(tx) - x0 + 0.5) * scale - 0.5, (np.asarray(ty) - y0 + 0.5) * scale - 0.5


def retexture(rgb: np.ndarray, mask: np.ndarray, texture: np.ndarray, tx: np.ndarray,
              ty: np.ndarray, threshold: float, f: float = 0.1) -> np.ndarray:
    """The object re-textured: ``(1 - f) G T(t) + f C_diffuse + highlights``.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear HDR photograph.
    mask : np.ndarray of bool
        The object's pixels.
    texture : np.ndarray
        ``(h, w, 3)`` texture, linear RGB (reflectance-like, nominally in [0, 1]).
    tx, ty : np.ndarray
        Warped image coordinates of every pixel.
    threshold : float
        Highlight luminance threshold (same unit as ``rgb``).
    f : float
        Weight of the original's diffuse part, in [0, 1].

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` float32: the photograph with the object re-textured.
    """
    rgb = np.asarray(rgb, np.float32)
    m = np.asarray(mask, bool)
    highlights = highlight_layer(rgb, m, threshold)
    diffuse = rgb - highlights
    shading = np.minimum(luminance(rgb), threshold)
    u, v = texture_coordinates(m, tx, ty, texture.shape[:2])
    t = sample(texture, u, v, wrap=True)
    edited = (1.0 - f) * shading[..., None] * t + f * diffuse + highlights
    return np.where(m[..., None], edited, rgb).astype(np.float32)
