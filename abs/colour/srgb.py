"""sRGB: the transfer functions between linear and encoded values, and relative luminance.

Linear values follow docs/conventions.md (Rec. 709 / sRGB primaries). The transfer functions are
the exact IEC 61966-2-1 pair; :mod:`abs.io.images` decodes 8- and 16-bit files with them,
:mod:`abs.colour.tonemap` encodes previews with them and :mod:`abs.metrics` compares images in
the encoded space. Plain numpy, so that the file formats below can use them (docs/architecture.md).
"""

from __future__ import annotations

import numpy as np

from abs.errors import InputError

__all__ = ["srgb_to_linear", "linear_to_srgb", "luminance", "as_rgb_image"]

# Rec. 709 luminance weights for linear RGB.
_LUMA = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """Decode sRGB-encoded values in [0, 1] to linear (exact IEC 61966-2-1 EOTF).

    Parameters
    ----------
    encoded : np.ndarray
        sRGB-encoded values, nominally in [0, 1].

    Returns
    -------
    np.ndarray
        Linear values, ``float32``.
    """
    c = np.asarray(encoded, dtype=np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """Encode linear values in [0, 1] with the exact sRGB OETF (inverse of :func:`srgb_to_linear`).

    Negative inputs are clamped to 0 first (the power law is undefined for them).
    """
    c = np.maximum(np.asarray(linear, dtype=np.float32), 0.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1.0 / 2.4) - 0.055).astype(np.float32)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec. 709 relative luminance ``Y`` of linear RGB, shape ``rgb.shape[:-1]``."""
    return np.asarray(rgb, dtype=np.float32) @ _LUMA


def as_rgb_image(rgb: np.ndarray) -> np.ndarray:
    """``rgb`` as an array, checked to be an image of shape ``(height, width, 3)``."""
    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InputError(None, "rgb", f"expected an array of shape (height, width, 3), "
                                      f"got {arr.shape}")
    return arr
