"""Sensor effects as a real camera produces them, for synthetic "photographs" in benchmarks.

abs fits simple sensor models (:mod:`abs.render.sensor`: a polynomial falloff, a constant offset,
a power-law response). Benchmarks that hide a sensor effect in their photographs should not
make them with those same models, so here each effect has a different, physically motivated
form (numpy, applied to a rendered radiance image of a :class:`~abs.render.camera.Camera`):

- :func:`natural_vignetting`: the cos^4 law of a thin lens, ``1 / (1 + (r / f_e)^2)^2`` with an
  effective exit-pupil scale, which the polynomial only approximates;
- :func:`veiling_glare`: light scattered in the lens, a wide Gaussian blur of the image itself
  (bright regions glow more), plus a uniform floor;
- :func:`filmic_response`: a saturating response ``x (1 + x / w^2) / (1 + x)`` (Reinhard's
  extended operator), not a power law;
- :func:`white_balance_shift`: the colours of a scene lit by another illuminant, by Bradford
  chromatic adaptation in XYZ (colour-science), which abs fits as a 3x3 colour matrix of linear
  RGB without knowing it is one.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.render.sensor import radial_moments

__all__ = ["natural_vignetting", "veiling_glare", "filmic_response", "white_balance_matrix",
           "white_balance_shift"]


def natural_vignetting(image: np.ndarray, camera, strength: float = 1.0) -> np.ndarray:
    """Image times ``cos^4`` of the field angle scaled by ``strength``: ``1 / (1 + s^2 r^2)^2``.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3)
        Linear radiance of ``camera``'s view.
    strength : float
        ``s`` (dimensionless); 1 is an ideal thin lens, 0 no falloff. To first order the falloff
        is ``1 - 2 s^2 r^2``, i.e. abs's ``k1 = -2 s^2``.
    """
    r2 = radial_moments(camera)[0]  # pixel-centre r^2 (block-averaged for downsampled cameras)
    return (image / np.square(1.0 + strength ** 2 * r2)[..., None]).astype(np.float32)


def veiling_glare(image: np.ndarray, fraction: float, sigma_px: float, floor=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Image plus ``fraction`` of itself blurred by a Gaussian of ``sigma_px`` pixels, plus
    ``floor`` (RGB, radiance units); the blur is energy-preserving (reflective borders)."""
    glare = cv2.GaussianBlur(np.asarray(image, np.float32), (0, 0), sigma_px,
                             borderType=cv2.BORDER_REFLECT)
    return (image + fraction * glare + np.asarray(floor, np.float32)).astype(np.float32)


def filmic_response(image: np.ndarray, white: float = 2.0) -> np.ndarray:
    """Reinhard's extended response ``x (1 + x / white^2) / (1 + x)``, per channel (``white``:
    the radiance that maps to 1)."""
    x = np.maximum(np.asarray(image, np.float64), 0.0)
    return (x * (1.0 + x / white ** 2) / (1.0 + x)).astype(np.float32)


def white_balance_matrix(cct: float) -> np.ndarray:
    """The 3x3 matrix on linear sRGB (the project's image convention) that Bradford-adapts
    colours from the rendering's white (D65) to the white of a Planckian-locus illuminant of
    ``cct`` kelvin: a white balance set for D65 while the light was ``cct`` (a warm cast below
    6504 K, a cold one above). Computed by colour-science, independently of abs's sensor."""
    import colour

    space = colour.RGB_COLOURSPACES["sRGB"]
    adapt = colour.adaptation.matrix_chromatic_adaptation_VonKries(
        colour.xy_to_XYZ(space.whitepoint), colour.xy_to_XYZ(colour.temperature.CCT_to_xy(cct)),
        "Bradford")
    return np.asarray(space.matrix_XYZ_to_RGB @ adapt @ space.matrix_RGB_to_XYZ, np.float64)


def white_balance_shift(image: np.ndarray, cct: float) -> np.ndarray:
    """``image`` (linear sRGB, (H, W, 3)) as photographed under a ``cct`` kelvin white balance
    error (:func:`white_balance_matrix`): a colour shift over the whole image."""
    m = white_balance_matrix(cct)
    return np.einsum("ij,hwj->hwi", m, np.asarray(image, np.float64)).astype(np.float32)
