"""Highlights: found at the minimum of the luminance histogram's derivative, kept through edits.

Khan et al. (2006) separate the object's specular highlights from the rest by a luminance
threshold placed where the histogram of the object's luminance falls most steeply: the minimum of
its derivative. Above it a pixel is a highlight. Edits that replace the object's appearance by
something else (glass, translucency, a new texture) add the highlights back, because they are the
cue that tells a viewer the surface is shiny and where the light is.

Our reading of the details the text leaves open: the histogram is of linear luminance over the
object's pixels, ``bins`` equal bins on ``[0, max]`` (by default ``sqrt(pixels)``, clipped to 16
to 256, so that the counts are not too noisy on small objects); its derivative is the forward
difference ``h[k+1] - h[k]``; its minimum is searched from the histogram's mode upwards (a fall
below the mode is the dark side of the body colour, not a highlight's edge); the threshold is the
edge between bins ``k*`` and ``k*+1``, so that the bins after the steepest fall are the
highlights. The highlight *layer* kept through an
edit is the part of each pixel's radiance above the threshold, ``C max(0, 1 - t / L)`` (the pixel's
colour scaled to its luminance excess).
"""

from __future__ import annotations

import numpy as np

from abs.colour.srgb import luminance

__all__ = ["default_bins", "highlight_threshold", "highlight_mask", "highlight_layer"]


def default_bins(pixels: int) -> int:
    """``sqrt(pixels)`` rounded, clipped to [16, 256]: the default histogram size."""
    return int(np.clip(round(np.sqrt(max(pixels, 1))), 16, 256))


def highlight_threshold(lum: np.ndarray, mask: np.ndarray | None = None,
                        bins: int | None = None) -> float:
    """Luminance at the minimum of the derivative of the object's luminance histogram.

    Parameters
    ----------
    lum : np.ndarray
        Luminance (linear radiance units).
    mask : np.ndarray of bool, optional
        The object's pixels (all when omitted).
    bins : int, optional
        Number of equal bins on ``[0, max(lum)]`` (>= 2); :func:`default_bins` when omitted.

    Returns
    -------
    float
        The threshold, same unit as ``lum``: the upper edge of bin ``k*``, where ``h[k*+1] -
        h[k*]`` is smallest over ``k*`` at or above the mode (the first such ``k*`` when tied).
    """
    values = np.asarray(lum, np.float64)
    if mask is not None:
        values = values[np.asarray(mask, bool)]
    values = np.maximum(values, 0.0)
    top = float(values.max()) if values.size else 0.0
    if top <= 0.0:
        return 0.0
    counts, edges = np.histogram(values, bins=bins or default_bins(values.size), range=(0.0, top))
    mode = int(np.argmax(counts))
    k = mode + int(np.argmin(np.diff(counts)[mode:])) if mode < counts.size - 1 else mode - 1
    return float(edges[k + 1])


def highlight_mask(lum: np.ndarray, mask: np.ndarray, threshold: float) -> np.ndarray:
    """Object pixels brighter than ``threshold`` (bool, shape of ``lum``)."""
    return np.asarray(mask, bool) & (np.asarray(lum) > threshold)


def highlight_layer(rgb: np.ndarray, mask: np.ndarray, threshold: float) -> np.ndarray:
    """The radiance above the highlight threshold, ``C max(0, 1 - t / L)`` on the object.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB.
    mask : np.ndarray of bool
        The object's pixels.
    threshold : float
        Luminance threshold (:func:`highlight_threshold`).

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` float32, zero off the object and below the threshold.
    """
    rgb = np.asarray(rgb, np.float64)
    lum = luminance(rgb).astype(np.float64)
    excess = np.divide(lum - threshold, lum, out=np.zeros_like(lum), where=lum > 0)
    excess = np.where(np.asarray(mask, bool), np.clip(excess, 0.0, 1.0), 0.0)
    return (rgb * excess[..., None]).astype(np.float32)
