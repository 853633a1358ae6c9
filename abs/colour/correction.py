"""Colour correction: linear camera RGB -> CIE XYZ -> the rendering colour space.

Model (Finlayson, Mackiewicz & Hurlbert 2015, "Color correction using root-polynomial
regression"): the camera RGB of a patch is expanded into root-polynomial terms of degree 2,
``[R, G, B, sqrt(RG), sqrt(GB), sqrt(RB)]``, and a 3x6 matrix maps them to XYZ. Every term scales
linearly with exposure, so the correction does too (a brighter photograph gives a proportionally
brighter XYZ). The matrix is fitted by least squares (colour-science's
``matrix_colour_correction_Finlayson2015``), then refined by minimising the mean CIEDE2000
difference in CIELAB with BFGS (scipy), as the seed does: least squares in XYZ weighs bright
patches most, while ΔE00 weighs what the eye (and a fit's residual image) sees.

Degree 1 is the plain linear 3x3 correction (the baseline).

CIELAB needs a reference white: the chart's illuminant (D50 for the ColorChecker references
colour-science ships), i.e. the XYZ of a perfect white diffuser under it, with ``Y = 1`` on the
scale of the reference XYZ values.

The corrected XYZ are finally expressed in the rendering colour space, by default **CIE RGB**
(primaries 700 / 546.1 / 435.8 nm, white E) with Bradford adaptation from the reference white,
so that a neutral patch under the chart's illuminant becomes R = G = B (colour-science's
``XYZ_to_RGB``). ``"sRGB"`` (linear Rec. 709, the project's image convention) is the other choice.
"""

from __future__ import annotations

from dataclasses import dataclass

import colour
import numpy as np
from scipy.optimize import minimize

from abs.errors import InputError

__all__ = ["OUTPUT_SPACES", "expand", "fit_matrix", "delta_e00", "refine_delta_e00",
           "xyz_to_output_matrix", "ColourCorrection", "calibrate"]

#: Rendering colour spaces a correction can end in (colour-science colourspace names).
OUTPUT_SPACES = ("CIE RGB", "sRGB")


def expand(rgb: np.ndarray, degree: int) -> np.ndarray:
    """Root-polynomial terms of camera RGB, shape ``(..., terms)`` (3 for degree 1, 6 for 2)."""
    return np.asarray(colour.characterisation.polynomial_expansion_Finlayson2015(
        np.asarray(rgb, dtype=np.float64), degree, root_polynomial_expansion=True))


def fit_matrix(rgb: np.ndarray, xyz: np.ndarray, degree: int) -> np.ndarray:
    """Least-squares matrix, shape ``(3, terms)``, mapping :func:`expand` of ``rgb`` to ``xyz``."""
    return np.asarray(colour.characterisation.matrix_colour_correction_Finlayson2015(
        np.asarray(rgb, np.float64), np.asarray(xyz, np.float64), degree,
        root_polynomial_expansion=True))


def delta_e00(xyz: np.ndarray, xyz_reference: np.ndarray, white_xyz: np.ndarray) -> np.ndarray:
    """CIEDE2000 difference per patch between two sets of XYZ, in CIELAB relative to ``white_xyz``.

    Parameters
    ----------
    xyz, xyz_reference : ndarray, shape (N, 3)
        Tristimulus values on one scale.
    white_xyz : ndarray, shape (3,)
        The reference white on that scale (its Y sets L* = 100).
    """
    white = np.asarray(white_xyz, np.float64)
    xy = colour.XYZ_to_xy(white)
    lab = colour.XYZ_to_Lab(np.asarray(xyz, np.float64) / white[1], xy)
    lab_ref = colour.XYZ_to_Lab(np.asarray(xyz_reference, np.float64) / white[1], xy)
    return np.asarray(colour.delta_E(lab, lab_ref, method="CIE 2000"))


def refine_delta_e00(matrix: np.ndarray, rgb: np.ndarray, xyz: np.ndarray, white_xyz: np.ndarray,
                     degree: int) -> np.ndarray:
    """Refine a correction matrix by minimising the mean ΔE00 over the patches with BFGS.

    Starts from ``matrix`` (the least-squares fit); the gradient is taken by finite differences
    (a few dozen parameters at most). The unknowns are the changes of the entries in units of the
    largest entry, so that BFGS's first steps and tolerance have a sensible scale whatever the
    units of RGB and XYZ. Returns the refined matrix, same shape.
    """
    terms = expand(rgb, degree)
    start = np.asarray(matrix, np.float64)
    scale = float(np.abs(start).max()) or 1.0

    def mean_de(step: np.ndarray) -> float:
        m = start + scale * step.reshape(start.shape)
        return float(delta_e00(terms @ m.T, xyz, white_xyz).mean())

    result = minimize(mean_de, np.zeros(start.size), method="BFGS", options={"gtol": 1e-4})
    # BFGS only moves downhill, but keep the start if round-off ever made it worse.
    if mean_de(result.x) > mean_de(np.zeros(start.size)):
        return start
    return start + scale * result.x.reshape(start.shape)


def xyz_to_output_matrix(white_xyz: np.ndarray, space: str = "CIE RGB") -> np.ndarray:
    """3x3 matrix from XYZ (relative to ``white_xyz``) to linear ``space`` RGB, Bradford-adapted
    so that ``white_xyz`` maps to R = G = B = its Y."""
    if space not in OUTPUT_SPACES:
        raise InputError(None, "space", f"unknown output space {space!r}; one of {OUTPUT_SPACES}")
    xy = colour.XYZ_to_xy(np.asarray(white_xyz, np.float64))
    # XYZ_to_RGB is linear: its matrix is its image of the identity's rows.
    return np.asarray(colour.XYZ_to_RGB(np.eye(3), space, illuminant=xy,
                                        chromatic_adaptation_transform="Bradford")).T


@dataclass(frozen=True)
class ColourCorrection:
    """A fitted colour correction (see the module docstring).

    Attributes
    ----------
    degree : int
        1 (linear 3x3) or 2 (root-polynomial).
    matrix : ndarray, shape (3, terms)
        Camera RGB terms -> XYZ (reference scale).
    white_xyz : ndarray, shape (3,)
        Reference white (CIELAB and the adaptation of the output space).
    space : str
        Output colour space, one of :data:`OUTPUT_SPACES`.
    xyz_to_rgb : ndarray, shape (3, 3)
        XYZ -> output space.
    delta_e_before, delta_e_after : ndarray, shape (N,)
        ΔE00 per patch of the least-squares fit and of the refined one (training patches).
    """

    degree: int
    matrix: np.ndarray
    white_xyz: np.ndarray
    space: str
    xyz_to_rgb: np.ndarray
    delta_e_before: np.ndarray
    delta_e_after: np.ndarray

    def to_xyz(self, rgb: np.ndarray) -> np.ndarray:
        """Linear camera RGB ``(..., 3)`` -> XYZ ``(..., 3)`` on the reference scale."""
        rgb = np.asarray(rgb, np.float64)
        if self.degree > 1:
            # Root terms of negative values (noise in dark pixels) are undefined: clamp at 0.
            rgb = np.maximum(rgb, 0.0)
        return expand(rgb, self.degree) @ self.matrix.T

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        """Linear camera RGB ``(..., 3)`` -> linear output-space RGB, ``float32``."""
        return (self.to_xyz(rgb) @ self.xyz_to_rgb.T).astype(np.float32)


def calibrate(rgb: np.ndarray, xyz: np.ndarray, white_xyz: np.ndarray, *, degree: int = 2,
              refine: bool = True, space: str = "CIE RGB") -> ColourCorrection:
    """Fit a colour correction to chart patches.

    Parameters
    ----------
    rgb : ndarray, shape (N, 3)
        Linear camera RGB of the patches (any exposure scale).
    xyz : ndarray, shape (N, 3)
        Their reference XYZ (e.g. :func:`abs.colour.chart.reference_xyz`, D50, white Y ~ 1).
    white_xyz : ndarray, shape (3,)
        XYZ of the reference white on the scale of ``xyz``.
    degree : int
        1 (linear) or 2 (root-polynomial, default).
    refine : bool
        Refine by minimising mean ΔE00 (BFGS) after least squares.
    space : str
        Output colour space (:data:`OUTPUT_SPACES`).

    Returns
    -------
    ColourCorrection
    """
    rgb = np.asarray(rgb, np.float64)
    xyz = np.asarray(xyz, np.float64)
    terms = 3 if degree == 1 else 6
    if degree not in (1, 2):
        raise InputError(None, "degree", f"expected 1 or 2, got {degree}")
    if rgb.shape != xyz.shape or rgb.ndim != 2 or rgb.shape[1] != 3:
        raise InputError(None, "patches", f"camera RGB {rgb.shape} and XYZ {xyz.shape} must both "
                                          "be (N, 3)")
    if rgb.shape[0] < terms + 1:
        raise InputError(None, "patches", f"{rgb.shape[0]} patches cannot fit {terms} terms per "
                                          "channel (need more patches than terms)")
    matrix = fit_matrix(rgb, xyz, degree)
    before = delta_e00(expand(rgb, degree) @ matrix.T, xyz, white_xyz)
    if refine:
        matrix = refine_delta_e00(matrix, rgb, xyz, white_xyz, degree)
    after = delta_e00(expand(rgb, degree) @ matrix.T, xyz, white_xyz)
    return ColourCorrection(degree, matrix, np.asarray(white_xyz, np.float64), space,
                            xyz_to_output_matrix(white_xyz, space), before, after)
