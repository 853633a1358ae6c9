"""Glass and translucency from the background behind the object (Khan et al. 2006, sec. 5).

The object becomes transparent by showing the filled background (:mod:`abs.editing.holes`) through
it, warped with the same indices as a texture, ``B(x + s grad d')`` (:mod:`abs.editing.warp`);
its highlights are then added back. Variants:

- **clear** glass: the warped background;
- **frosted** glass: blurred a little (Gaussian, sigma 0.05 of the object's equivalent radius,
  our choice);
- **translucent**: blurred a lot (sigma 0.3 of the radius, our choice);
- **tinted** glass: a colour transfer (Reinhard et al. 2001, in Ruderman's l-alpha-beta space)
  that gives the warped background the object's own colour statistics. Our choice: only the two
  chromatic channels (alpha, beta) are transferred; ``l`` is kept, so the glass stays as bright as
  what lies behind it;
- **dark** glass: ``C'' = C_max (C' / C_max)^a`` with ``a`` about 1.2 to 1.4 (1.3 by default) and
  ``C_max`` the largest value of ``C'`` over the object (all channels).
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.editing.warp import equivalent_radius, sample

__all__ = ["FROSTED_BLUR", "TRANSLUCENT_BLUR", "DARK_EXPONENT", "see_through", "blur",
           "rgb_to_lab_ruderman", "lab_ruderman_to_rgb", "transfer_colour", "darken"]

FROSTED_BLUR = 0.05
"""Frosted glass: Gaussian sigma as a fraction of the object's equivalent radius (our choice)."""
TRANSLUCENT_BLUR = 0.3
"""Translucency: Gaussian sigma as a fraction of the object's equivalent radius (our choice)."""
DARK_EXPONENT = 1.3
"""Dark glass exponent ``a`` (the paper: about 1.2 to 1.4)."""

_RGB_TO_LMS = np.array([[0.3811, 0.5783, 0.0402],
                        [0.1967, 0.7244, 0.0782],
                        [0.0241, 0.1288, 0.8444]])
_LMS_TO_LAB = (np.diag([1 / np.sqrt(3), 1 / np.sqrt(6), 1 / np.sqrt(2)])
               @ np.array([[1.0, 1.0, 1.0], [1.0, 1.0, -2.0], [1.0, -1.0, 0.0]]))
_LMS_FLOOR = 1e-6


def see_through(background: np.ndarray, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
    """The filled background at the warped coordinates, float32 ``(height, width, 3)``."""
    return sample(background, tx, ty, wrap=False)


def blur(image: np.ndarray, mask: np.ndarray, fraction: float) -> np.ndarray:
    """Gaussian blur with sigma ``fraction`` times the object's equivalent radius (pixels)."""
    sigma = fraction * equivalent_radius(mask)
    if sigma <= 0:
        return np.asarray(image, np.float32)
    return cv2.GaussianBlur(np.ascontiguousarray(image, np.float32), (0, 0), sigma,
                            borderType=cv2.BORDER_REFLECT_101)


def rgb_to_lab_ruderman(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB to Ruderman's l-alpha-beta (log10 LMS, decorrelated), as Reinhard et al. 2001."""
    lms = np.maximum(np.asarray(rgb, np.float64) @ _RGB_TO_LMS.T, _LMS_FLOOR)
    return np.log10(lms) @ _LMS_TO_LAB.T


def lab_ruderman_to_rgb(lab: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rgb_to_lab_ruderman`."""
    lms = 10.0 ** (np.asarray(lab, np.float64) @ np.linalg.inv(_LMS_TO_LAB).T)
    return lms @ np.linalg.inv(_RGB_TO_LMS).T


def transfer_colour(target: np.ndarray, source: np.ndarray, channels=(1, 2)) -> np.ndarray:
    """Reinhard et al.'s colour transfer: give ``target`` the mean and sd of ``source``.

    Parameters
    ----------
    target : np.ndarray
        ``(..., 3)`` linear RGB to recolour.
    source : np.ndarray
        ``(..., 3)`` linear RGB whose statistics are imposed.
    channels : tuple of int
        l-alpha-beta channels transferred (0 = l, 1 = alpha, 2 = beta); ``(1, 2)`` keeps the
        target's lightness.

    Returns
    -------
    np.ndarray
        ``target``'s shape, float32 linear RGB.
    """
    t = rgb_to_lab_ruderman(np.reshape(target, (-1, 3)))
    s = rgb_to_lab_ruderman(np.reshape(source, (-1, 3)))
    for c in channels:
        sd_t = t[:, c].std()
        scale = s[:, c].std() / sd_t if sd_t > 0 else 1.0
        t[:, c] = (t[:, c] - t[:, c].mean()) * scale + s[:, c].mean()
    return lab_ruderman_to_rgb(t).reshape(np.shape(target)).astype(np.float32)


def darken(rgb: np.ndarray, mask: np.ndarray, a: float = DARK_EXPONENT) -> np.ndarray:
    """Dark glass: ``C_max (C / C_max)^a`` on the object's pixels, ``C_max`` their largest value.

    Returns
    -------
    np.ndarray
        ``rgb``'s shape, float32; off-object pixels unchanged.
    """
    rgb = np.asarray(rgb, np.float64)
    m = np.asarray(mask, bool)
    c_max = float(rgb[m].max()) if m.any() else 0.0
    out = rgb.copy()
    if c_max > 0:
        out[m] = c_max * (np.maximum(rgb[m], 0.0) / c_max) ** a
    return out.astype(np.float32)
