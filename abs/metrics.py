"""Compare a rendering with a photograph: RMSE, SSIM and a per-pixel log error.

Images follow docs/conventions.md: linear RGB arrays of shape ``(height, width, 3)``, in the
radiance units of the photograph (so RMSE is in those units too). Masks are ``(height, width)``
boolean arrays whose True pixels are compared.

Every function refuses NaN or infinite values with :class:`abs.errors.InputError` (a
``ValueError``): a metric silently turned NaN would make every later comparison meaningless.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.errors import InputError
from abs.colour.srgb import linear_to_srgb

__all__ = ["rmse", "ssim", "log_error", "reinhard", "log_average_luminance", "ciede2000_image"]

#: Error below which :func:`log_error` clamps, so that a perfect pixel maps to -6, not -inf.
LOG_ERROR_FLOOR = 1e-6


def _image_pair(rendering: np.ndarray, photograph: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both images as ``float64`` after checking shapes match and values are finite."""
    a = np.asarray(rendering, dtype=np.float64)
    b = np.asarray(photograph, dtype=np.float64)
    for name, arr in (("rendering", a), ("photograph", b)):
        if arr.ndim != 3 or arr.shape[2] != 3 or arr.size == 0:
            raise InputError(None, name, f"expected an array of shape (height, width, 3), "
                                         f"got {arr.shape}")
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        if bad:
            raise InputError(None, name, f"{bad} non-finite values (NaN or Inf)")
    if a.shape != b.shape:
        raise InputError(None, "rendering", f"shape {a.shape} differs from the photograph's "
                                            f"{b.shape}")
    return a, b


def _pixel_mask(mask: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """A ``(height, width)`` bool mask (all True when ``mask`` is None) that selects something."""
    if mask is None:
        return np.ones(shape[:2], dtype=bool)
    m = np.asarray(mask)
    if m.shape != shape[:2]:
        raise InputError(None, "mask", f"expected shape {shape[:2]}, got {m.shape}")
    m = m.astype(bool)
    if not m.any():
        raise InputError(None, "mask", "selects no pixel, so there is nothing to compare")
    return m


def rmse(rendering: np.ndarray, photograph: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Root mean square difference over pixels and colour channels.

    Parameters
    ----------
    rendering, photograph : np.ndarray
        ``(height, width, 3)`` linear RGB, same shape and units.
    mask : np.ndarray, optional
        ``(height, width)`` bool; only True pixels count. Default: every pixel.

    Returns
    -------
    float
        ``sqrt(mean((rendering - photograph)**2))`` over the selected pixels and all three
        channels, in the images' radiance units.

    Raises
    ------
    InputError
        If shapes differ or are not ``(height, width, 3)``, a value is NaN or infinite, or the
        mask has the wrong shape or selects no pixel.
    """
    a, b = _image_pair(rendering, photograph)
    selected = _pixel_mask(mask, a.shape)
    return float(np.sqrt(np.mean((a[selected] - b[selected]) ** 2)))


def ssim(rendering: np.ndarray, photograph: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Structural similarity of the two images as a viewer sees them.

    Both images are tone-mapped the same way (clipped to [0, 1], sRGB-encoded, scaled to
    [0, 255] because OpenCV's SSIM constants assume that range) and compared with OpenCV
    contrib's :func:`cv2.quality.QualitySSIM_compute` (11x11 Gaussian window, sigma 1.5). The
    SSIM map is averaged over the masked pixels and the three channels.

    Parameters
    ----------
    rendering, photograph : np.ndarray
        ``(height, width, 3)`` linear RGB, same shape. Values above 1 clip, so scale the images
        to a displayable exposure first if they are in other units.
    mask : np.ndarray, optional
        ``(height, width)`` bool; only True pixels of the SSIM map count. The window still
        reads unmasked pixels within 5 pixels of the mask's border.

    Returns
    -------
    float
        Mean SSIM, dimensionless, 1 for identical images (after tone mapping).

    Raises
    ------
    InputError
        As :func:`rmse`.
    """
    a, b = _image_pair(rendering, photograph)
    selected = _pixel_mask(mask, a.shape)
    ref, cmp = (255.0 * linear_to_srgb(np.clip(x, 0.0, 1.0)).astype(np.float64) for x in (b, a))
    _, quality_map = cv2.quality.QualitySSIM_compute(ref, cmp)
    return float(np.mean(quality_map[selected]))


def log_error(rendering: np.ndarray, photograph: np.ndarray) -> np.ndarray:
    """Base-10 logarithm of the per-pixel RGB distance, for error images.

    Parameters
    ----------
    rendering, photograph : np.ndarray
        ``(height, width, 3)`` linear RGB, same shape and units.

    Returns
    -------
    np.ndarray
        ``float64`` array of shape ``(height, width)``:
        ``log10(max(sqrt(sum_c (rendering - photograph)**2), 1e-6))``, so a pixel with no error
        is -6 rather than -inf. Units: log10 of the images' radiance units.

    Raises
    ------
    InputError
        If shapes differ or are not ``(height, width, 3)``, or a value is NaN or infinite.
    """
    a, b = _image_pair(rendering, photograph)
    distance = np.sqrt(np.sum((a - b) ** 2, axis=-1))
    return np.log10(np.maximum(distance, LOG_ERROR_FLOOR))


# -- the structured-light study's colour difference (also abs.appearance's metric) ----------
# Reinhard's global operator (key 0.18 on the log-average luminance of a reference image,
# L/(1 + L) on luminance, colours scaled with it), a 2.2 display gamma, CIELAB (D65), CIEDE2000.

GAMMA = 2.2
REINHARD_KEY = 0.18


def reinhard(rgb: np.ndarray, log_average: float) -> np.ndarray:
    """Reinhard's global operator and a 2.2 gamma: display RGB in [0, 1].

    Parameters
    ----------
    rgb : np.ndarray
        (..., 3) linear RGB radiance.
    log_average : float
        Log-average luminance the key 0.18 is applied to (the same for images compared).
    """
    lum = np.maximum(rgb @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    scaled = REINHARD_KEY / log_average * lum
    display_lum = scaled / (1.0 + scaled)
    ratio = np.where(lum > 0.0, display_lum / np.where(lum > 0.0, lum, 1.0), 0.0)
    return np.clip(np.maximum(rgb, 0.0) * ratio[..., None], 0.0, 1.0) ** (1.0 / GAMMA)


def log_average_luminance(rgb: np.ndarray, delta: float = 1e-4) -> float:
    """exp(mean(log(δ + L))) over all pixels (Reinhard et al. 2002)."""
    lum = np.maximum(rgb @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    return float(np.exp(np.mean(np.log(delta + lum))))


def ciede2000_image(display_a: np.ndarray, display_b: np.ndarray) -> np.ndarray:
    """Per-pixel CIEDE2000 between two gamma-2.2 display images (..., 3) in [0, 1]."""
    import colour

    space = colour.models.RGB_COLOURSPACE_sRGB
    labs = []
    for display in (display_a, display_b):
        xyz = (np.asarray(display, np.float64) ** GAMMA) @ space.matrix_RGB_to_XYZ.T
        labs.append(colour.XYZ_to_Lab(xyz, space.whitepoint))
    return colour.difference.delta_E_CIE2000(labs[0], labs[1])
