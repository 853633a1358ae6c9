"""Tone mapping of linear RGB to 8-bit sRGB previews (reports, PNG previews), never data."""

from __future__ import annotations

import numpy as np

from abs.colour.srgb import as_rgb_image, linear_to_srgb, luminance

__all__ = ["auto_exposure", "tonemap"]


def auto_exposure(rgb: np.ndarray) -> float:
    """Exposure :func:`tonemap` picks by default: the 99th percentile of luminance maps to 0.9.

    Computing it once from a photograph and passing it to :func:`tonemap` for the renderings of
    the same view shows them all at the same exposure.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB; non-finite values are ignored.

    Returns
    -------
    float
        Linear multiplier; 1.0 when the image is black (or has no finite value).
    """
    lum = luminance(as_rgb_image(rgb))
    lum = lum[np.isfinite(lum)]
    p99 = float(np.percentile(lum, 99)) if lum.size else 0.0
    return 0.9 / p99 if p99 > 0 else 1.0


def tonemap(rgb: np.ndarray, exposure: float | None = None) -> np.ndarray:
    """Tone-map linear RGB to 8-bit sRGB for display.

    The image is multiplied by ``exposure``; when that is ``None`` the factor is chosen so that
    the 99th percentile of the (finite) luminance maps to 0.9, keeping highlights just below
    white. The result is clipped to [0, 1] (NaN → 0) and sRGB-encoded. No curve, no colour
    grading: previews only, never data.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB.
    exposure : float, optional
        Linear multiplier applied before clipping (1.0 shows the values as they are).

    Returns
    -------
    np.ndarray
        ``uint8`` array of shape ``(height, width, 3)``, sRGB-encoded RGB.
    """
    arr = as_rgb_image(rgb).astype(np.float32)
    if exposure is None:
        exposure = auto_exposure(arr)
    scaled = np.nan_to_num(arr * np.float32(exposure), nan=0.0, posinf=1.0, neginf=0.0)
    encoded = linear_to_srgb(np.clip(scaled, 0.0, 1.0))
    return np.round(encoded * 255.0).astype(np.uint8)
