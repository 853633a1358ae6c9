"""More or less gloss by remapping the highlights' luminance (Khan et al. 2006, Eqs. 18-19).

The paper makes an object glossier or more diffuse without any shape: it remaps the luminance of
the highlight pixels (those above :func:`abs.editing.highlights.highlight_threshold`) with a curve
of two parameters, ``alpha = 0.05`` and ``beta = 20`` for a more specular look, ``beta = 0.05``
for a more diffuse one.

**Not found:** the verbatim Eqs. 18-19 (the paper's text was not in the material we could
search; only the parameter values above are known to us, from the issue). **Our choice**, built to
match what those values do: on the highlight's normalised luminance ``x = (L - t) / (L_max - t)``
in [0, 1] (``t`` the threshold),

    g(x) = ((x + alpha)^beta - alpha^beta) / ((1 + alpha)^beta - alpha^beta),
    L'   = t + (L_max - t) g(x),

a power curve offset by ``alpha`` (which keeps ``beta < 1`` from a vertical slope at 0) and
normalised so that ``g(0) = 0`` and ``g(1) = 1``: the highlight meets the rest of the object
continuously and keeps its peak. ``beta > 1`` pushes the highlight's flanks down, leaving a
small, sharp core (glossier); ``beta < 1`` lifts them towards the peak, spreading the highlight
over its whole region with less contrast (more diffuse). Colour is kept: RGB is scaled by ``L' /
L``.
"""

from __future__ import annotations

import numpy as np

from abs.colour.srgb import luminance

__all__ = ["GLOSS_ALPHA", "GLOSSIER_BETA", "DIFFUSE_BETA", "gloss_curve", "remap_gloss"]

GLOSS_ALPHA = 0.05
"""The paper's alpha (dimensionless)."""
GLOSSIER_BETA = 20.0
"""The paper's beta for a more specular look."""
DIFFUSE_BETA = 0.05
"""The paper's beta for a more diffuse look."""


def gloss_curve(x: np.ndarray, alpha: float = GLOSS_ALPHA, beta: float = GLOSSIER_BETA) -> np.ndarray:
    """``g(x) = ((x + a)^b - a^b) / ((1 + a)^b - a^b)`` on [0, 1] (our form, module docstring).

    Parameters
    ----------
    x : np.ndarray
        Normalised highlight luminance, clipped to [0, 1].
    alpha, beta : float
        Offset (> 0) and exponent (> 0), dimensionless.

    Returns
    -------
    np.ndarray
        Values in [0, 1], ``g(0) = 0``, ``g(1) = 1``, increasing.
    """
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    low = alpha ** beta
    return ((x + alpha) ** beta - low) / ((1.0 + alpha) ** beta - low)


def remap_gloss(rgb: np.ndarray, mask: np.ndarray, threshold: float, alpha: float = GLOSS_ALPHA,
                beta: float = GLOSSIER_BETA) -> np.ndarray:
    """The photograph with the object's highlights remapped by :func:`gloss_curve`.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB.
    mask : np.ndarray of bool
        The object's pixels.
    threshold : float
        Highlight luminance threshold ``t`` (same unit as the image).
    alpha, beta : float
        Curve parameters (0.05 and 20 glossier, 0.05 and 0.05 more diffuse).

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` float32; pixels off the object or at or below ``t`` unchanged.
    """
    rgb = np.asarray(rgb, np.float64)
    lum = luminance(rgb).astype(np.float64)
    m = np.asarray(mask, bool)
    high = m & (lum > threshold)
    out = rgb.copy()
    if not high.any():
        return out.astype(np.float32)
    top = float(lum[m].max())
    span = top - threshold
    if span <= 0:
        return out.astype(np.float32)
    x = (lum[high] - threshold) / span
    new = threshold + span * gloss_curve(x, alpha, beta)
    out[high] = rgb[high] * (new / lum[high])[:, None]
    return out.astype(np.float32)
