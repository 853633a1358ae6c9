"""Depth from luminance: Khan et al. (2006), "Image-Based Material Editing", section 3.

The paper's shape estimate is "dark is deep": the object's luminance, compressed by a sigmoid,
smoothed by a bilateral filter (which removes texture and noise but keeps the silhouette's and
the shading's large steps), and expanded again by the inverse of the same sigmoid:

    L_s  = L^n / (L^n + sigma^n)                       (sigmoid, n = 0.73)
    d    = bilateral(L_s; sigma_spatial, sigma_L)
    d'   = (-sigma^n d / (d - 1))^(1/n) = sigma (d / (1 - d))^(1/n)   (inverse sigmoid)

with ``sigma`` the log-average luminance of the object's pixels. ``d'`` has the units of
luminance; the paper leaves the depth's unit open. :func:`depth_from_luminance` therefore also
scales it to pixels (our choice, documented there) so that gradients are slopes and the normals
of :mod:`abs.editing.gradients` are those of a surface of a plausible relief.

The bilateral filter is OpenCV's (``cv2.bilateralFilter``, float32, one channel).
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.colour.srgb import luminance

__all__ = ["SIGMOID_EXPONENT", "log_average_luminance", "sigmoid", "inverse_sigmoid",
           "bilateral", "depth_from_luminance"]

SIGMOID_EXPONENT = 0.73
"""The paper's sigmoid exponent ``n`` (dimensionless)."""

#: Offset added to luminance before its logarithm (Reinhard et al. 2002), same unit as L.
LOG_DELTA = 1e-6


def log_average_luminance(lum: np.ndarray, mask: np.ndarray | None = None,
                          delta: float = LOG_DELTA) -> float:
    """``exp(mean(log(delta + L)))`` over the masked pixels: the sigmoid's ``sigma``.

    Parameters
    ----------
    lum : np.ndarray
        Luminance (any shape), linear radiance units.
    mask : np.ndarray of bool, optional
        Pixels to average over (the object's); all when omitted.
    delta : float
        Small offset keeping ``log`` finite at black pixels, same unit as ``lum``.

    Returns
    -------
    float
        The log-average luminance, same unit as ``lum``.
    """
    values = np.asarray(lum, np.float64)
    if mask is not None:
        values = values[np.asarray(mask, bool)]
    return float(np.exp(np.mean(np.log(delta + np.maximum(values, 0.0)))))


def sigmoid(lum: np.ndarray, sigma: float, n: float = SIGMOID_EXPONENT) -> np.ndarray:
    """Sigmoidal compression ``L^n / (L^n + sigma^n)`` (the paper's depth section).

    Parameters
    ----------
    lum : np.ndarray
        Luminance >= 0 (negative values are clamped to 0), linear radiance units.
    sigma : float
        Semi-saturation luminance (> 0), same unit: ``L = sigma`` maps to 0.5.
    n : float
        Exponent (dimensionless), 0.73 in the paper.

    Returns
    -------
    np.ndarray
        Compressed values in [0, 1), float64.
    """
    ln = np.maximum(np.asarray(lum, np.float64), 0.0) ** n
    return ln / (ln + float(sigma) ** n)


def inverse_sigmoid(d: np.ndarray, sigma: float, n: float = SIGMOID_EXPONENT,
                    eps: float = 1e-6) -> np.ndarray:
    """The inverse of :func:`sigmoid`: ``d' = (-sigma^n d / (d - 1))^(1/n)``.

    Parameters
    ----------
    d : np.ndarray
        Compressed values; clipped to ``[0, 1 - eps]`` (the inverse diverges at 1).
    sigma, n : float
        As in :func:`sigmoid`.
    eps : float
        Margin below 1.

    Returns
    -------
    np.ndarray
        Values in the unit of ``sigma`` (luminance), float64.
    """
    d = np.clip(np.asarray(d, np.float64), 0.0, 1.0 - eps)
    return (-(float(sigma) ** n) * d / (d - 1.0)) ** (1.0 / n)


def bilateral(values: np.ndarray, sigma_spatial: float, sigma_range: float) -> np.ndarray:
    """OpenCV's bilateral filter of a one-channel image.

    Parameters
    ----------
    values : np.ndarray
        ``(height, width)`` image.
    sigma_spatial : float
        Spatial standard deviation in pixels (> 0).
    sigma_range : float
        Range standard deviation, in the unit of ``values``.

    Returns
    -------
    np.ndarray
        Filtered ``(height, width)`` float64 image.
    """
    src = np.ascontiguousarray(values, np.float32)
    # Kernel diameter: 3 sigma either side, at least the 3x3 neighbourhood.
    diameter = max(3, 2 * int(np.ceil(3.0 * sigma_spatial)) + 1)
    out = cv2.bilateralFilter(src, diameter, float(sigma_range), float(sigma_spatial),
                              borderType=cv2.BORDER_REFLECT)
    return out.astype(np.float64)


def depth_from_luminance(rgb: np.ndarray, mask: np.ndarray, *, n: float = SIGMOID_EXPONENT,
                         spatial_fraction: float = 0.008, sigma_range: float = 0.1,
                         relief: float = 1.0) -> np.ndarray:
    """The paper's depth map of the object: sigmoid, bilateral filter, inverse sigmoid.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear HDR photograph.
    mask : np.ndarray of bool
        ``(height, width)``: the object's pixels.
    n : float
        Sigmoid exponent (0.73).
    spatial_fraction : float
        The bilateral filter's spatial sigma as a fraction of the image width (the paper gives
        0.001 to 0.008; 0.008, the upper end, is the default because abs's test images are small),
        dimensionless.
    sigma_range : float
        The bilateral filter's range sigma, in units of the sigmoid's output ([0, 1]). The paper
        names it but the text we could find does not give its value; 0.1 is our choice.
    relief : float
        Our addition: the inverse sigmoid gives depth in luminance units, which the paper leaves
        unscaled. We divide it by its maximum over the object and multiply by ``relief`` times
        the object's equivalent radius ``sqrt(area / pi)`` in pixels, so that ``relief = 1``
        gives a depth range like a sphere's and gradients are slopes (pixels per pixel).

    Returns
    -------
    np.ndarray
        ``(height, width)`` float64 depth towards the viewer in pixels (larger is nearer), 0
        outside the object.
    """
    mask = np.asarray(mask, bool)
    lum = luminance(rgb).astype(np.float64)
    sigma = log_average_luminance(lum, mask)
    compressed = sigmoid(lum, sigma, n)
    sigma_spatial = max(spatial_fraction * lum.shape[1], 1e-3)
    smoothed = bilateral(compressed, sigma_spatial, sigma_range)
    depth = np.where(mask, inverse_sigmoid(smoothed, sigma, n), 0.0)
    peak = float(depth[mask].max()) if mask.any() else 0.0
    if peak <= 0.0:
        return np.zeros_like(depth)
    radius = np.sqrt(mask.sum() / np.pi)
    return depth / peak * relief * radius
