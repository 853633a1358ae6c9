"""Spectral quantities to per-channel (R, G, B) values with the CIE 1931 RGB colour-matching functions.

A refractive index is not a colour but a sparse sampling of the spectrum: the value a channel
sees is the spectrum averaged with that channel's sensitivity. Here the sensitivities are the
CIE 1931 RGB colour-matching functions (Wright & Guild 2° r̄ ḡ b̄, primaries 700 / 546.1 /
435.8 nm, as shipped by colour-science), each normalised to unit integral over 380-780 nm:

    x_c = ∫ x(λ) w_c(λ) dλ,    w_c = c̄(λ) / ∫ c̄(λ) dλ,    c ∈ {R, G, B}

so a constant spectrum stays the same constant in every channel. r̄ has a small negative lobe
(about 440-545 nm, down to -9 % of its peak): it is kept as published, so the R value is a
signed-weight average that can fall slightly outside the range of x over the red band.

Beer-Lambert absorption: a wave of vacuum wavelength λ in a medium with extinction coefficient
k decays in intensity as ``exp(-4πk/λ · d)``, so the absorption coefficient per metre is
``α(λ) = 4πk(λ)/λ`` (λ in metres), integrated per channel like any other spectrum.
"""

from __future__ import annotations

import colour
import numpy as np

from abs.colour.refractiveindex import OpticalConstants
from abs.errors import InputError

__all__ = ["CMFS_NAME", "channel_weights", "channel_centroids_m", "spectrum_to_rgb",
           "optical_constants_rgb"]

#: colour-science's name of the colour-matching functions used for every channel integral.
CMFS_NAME = "Wright & Guild 1931 2 Degree RGB CMFs"


def channel_weights() -> tuple[np.ndarray, np.ndarray]:
    """Wavelengths [m] and per-channel weights [1/m] of the normalised CIE 1931 RGB CMFs.

    Returns
    -------
    wavelength_m : ndarray, shape (N,)
        380-780 nm in 5 nm steps, in metres.
    weights : ndarray, shape (N, 3)
        ``w_c(λ)`` per R, G, B; the trapezoidal integral of each column over ``wavelength_m``
        is exactly 1.
    """
    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    wavelength_m = np.asarray(cmfs.wavelengths, dtype=np.float64) * 1e-9
    values = np.asarray(cmfs.values, dtype=np.float64)
    return wavelength_m, values / np.trapezoid(values, wavelength_m, axis=0)


def channel_centroids_m() -> np.ndarray:
    """Weighted mean wavelength [m] of each channel, ``∫ λ w_c(λ) dλ``, shape (3,)."""
    lam, w = channel_weights()
    return np.trapezoid(lam[:, None] * w, lam, axis=0)


def spectrum_to_rgb(spectrum) -> np.ndarray:
    """Integrate a spectrum against the normalised channel weights.

    Parameters
    ----------
    spectrum : callable
        Maps wavelengths [m] (ndarray) to values of the same shape, any unit; it is evaluated
        over 380-780 nm.

    Returns
    -------
    ndarray, shape (3,)
        Per-channel averages R, G, B in the spectrum's unit.
    """
    lam, w = channel_weights()
    values = np.asarray(spectrum(lam), dtype=np.float64)
    return np.trapezoid(values[:, None] * w, lam, axis=0)


def optical_constants_rgb(constants: OpticalConstants, *, require_k: bool = True) -> dict:
    """Per-channel refractive index, extinction and Beer-Lambert absorption of a material.

    Parameters
    ----------
    constants : OpticalConstants
        From :func:`abs.colour.read_refractiveindex_yaml`; ``n`` and ``k`` must cover 380-780 nm.
    require_k : bool
        Raise when the file has no ``k`` (default); otherwise return ``k`` and absorption as
        ``None``.

    Returns
    -------
    dict
        ``ior_rgb`` (n per R, G, B), ``k_rgb`` (extinction per channel, dimensionless) and
        ``absorption_per_m`` (``∫ 4πk/λ w_c dλ`` per channel, 1/m), plus ``source`` (the file)
        and ``references`` (its REFERENCES text) and ``cmfs`` (the weights used).

    Raises
    ------
    InputError
        Naming the file and field ``DATA``: no ``k`` (when required), or a range not covering
        the visible band.
    """
    if require_k and not constants.has_k:
        raise InputError(constants.source, "DATA", "no extinction coefficient k (needs a "
                         "'tabulated k' or 'tabulated nk' block) to derive the absorption")
    result = {"ior_rgb": spectrum_to_rgb(constants.n).tolist(), "k_rgb": None,
              "absorption_per_m": None}
    if constants.has_k:
        result["k_rgb"] = spectrum_to_rgb(constants.k).tolist()
        result["absorption_per_m"] = spectrum_to_rgb(
            lambda lam: 4.0 * np.pi * constants.k(lam) / lam).tolist()
    result.update(source=constants.source, references=constants.references, cmfs=CMFS_NAME)
    return result
