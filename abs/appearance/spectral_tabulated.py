"""abs's MERL-table BSDF in a spectral Mitsuba variant: each RGB table entry upsampled to a spectrum.

abs's ``abs_tabulated`` (:mod:`abs.render.bsdfs.tabulated`) returns an RGB triple per lookup; in a
spectral variant a BSDF must return its value at the path's sampled wavelengths, so that plugin
cannot run there (Mitsuba refuses it: it is registered for the RGB variant it was defined under).
This module defines the same BSDF for a spectral variant: the same Rusinkiewicz lookup and
trilinear blend (imported from the RGB plugin), but each of the 8 neighbouring table entries is
evaluated as a smooth spectrum before blending.

Upsampling: every entry's RGB value ``c`` (1/sr, may exceed 1) is stored as the coefficients of
Mitsuba's sRGB spectral model (Jakob and Hanika 2019, ``mi.srgb_model_fetch``) for ``c / s`` and
a scale ``s = 2 max(c)``, as pbrt-v4's ``RGBUnboundedSpectrum`` does; the spectrum is
``s · srgb_model_eval(coefficients, λ)``. (Mitsuba 3.9's own ``srgb`` spectrum cannot do this: it
clamps a colour above 1 to a flat spectrum of 1, even with ``unbounded``.) An entry of a single bounce under a white light thus
renders to (nearly) the RGB it had; products along a path differ from RGB products, as they do
for any spectral renderer. The coefficients (1.46 M entries, about 10 s of scalar look-ups) are
cached per table file (``<cache>/appearance/<name>.<digest>.srgb.npy``).

Import this module only after a spectral variant is active: the class subclasses that variant's
``mi.BSDF``. Plugin name: ``abs_tabulated`` (registered for the spectral variant only).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.io.merl import read_merl
from abs.io.shared_data import cache_dir
from abs.render.bsdfs.tabulated import PLUGIN_NAME, cosine_sampled, table_corners
from abs.render.jit import from_numpy

__all__ = ["PLUGIN_NAME", "SpectralTabulatedBSDF", "spectral_coefficients", "srgb_model",
           "register"]

if not mi.variant() or not mi.is_spectral:
    raise ImportError(f"{__name__} needs a spectral Mitsuba variant active before import, "
                      f"not {mi.variant()!r}")

_COEFFS = 4  # three sRGB-model coefficients and the scale, per table entry


def spectral_coefficients(table: np.ndarray) -> np.ndarray:
    """Per-entry sRGB spectral-model coefficients and scale of an RGB BRDF table.

    Parameters
    ----------
    table : np.ndarray
        ``(3, N)`` or flat ``3 N`` RGB values (1/sr), MERL order (channel-major).

    Returns
    -------
    np.ndarray
        ``(N, 4)`` float32: coefficients ``c0, c1, c2`` of ``mi.srgb_model_eval`` for ``c / s`` and
        the scale ``s = 2 max(c)`` (negative entries clamped to 0, a black entry has ``s = 0``).
    """
    rgb = np.maximum(np.asarray(table, np.float64).reshape(3, -1).T, 0.0)
    scale = 2.0 * rgb.max(axis=1)
    safe = np.where(scale > 0, scale, 1.0)
    unit = rgb / safe[:, None]
    out = np.zeros((len(rgb), _COEFFS), np.float32)
    out[:, 3] = scale
    fetch, colour = mi.srgb_model_fetch, mi.ScalarColor3f
    # The model is a precomputed 3D table inside Mitsuba reachable only per scalar colour; equal
    # colours (the many exact zeros, repeated entries) are looked up once.
    unique, inverse = np.unique(unit.astype(np.float32), axis=0, return_inverse=True)
    coeffs = np.array([list(fetch(colour(*map(float, c)))) for c in unique], np.float32)
    out[:, :3] = coeffs[inverse.reshape(-1)]
    return out


def srgb_model(coefficients: np.ndarray, wavelengths: np.ndarray) -> np.ndarray:
    """Mitsuba's sRGB spectral model in numpy (``mi.srgb_model_eval``), times the scale.

    Parameters
    ----------
    coefficients : np.ndarray
        ``(..., 4)``: ``c0, c1, c2`` and the scale ``s``, as :func:`spectral_coefficients` gives.
    wavelengths : np.ndarray
        Wavelengths, nm.

    Returns
    -------
    np.ndarray
        ``(..., len(wavelengths))``: ``s · (1/2 + v / (2 sqrt(1 + v²)))``, ``v = (c0 λ + c1) λ + c2``.
    """
    c = np.asarray(coefficients, np.float64)[..., None, :]
    lam = np.asarray(wavelengths, np.float64)
    v = (c[..., 0] * lam + c[..., 1]) * lam + c[..., 2]
    return c[..., 3] * (0.5 + 0.5 * v / np.sqrt(1.0 + v * v))


def _cached_coefficients(path: Path) -> np.ndarray:
    data = path.read_bytes()
    digest = hashlib.sha256(data).hexdigest()[:16]
    cached = cache_dir("appearance") / f"{path.stem}.{digest}.srgb.npy"
    if cached.is_file():
        return np.load(cached, allow_pickle=False)
    coefficients = spectral_coefficients(read_merl(path))
    tmp = cached.with_suffix(".tmp.npy")
    np.save(tmp, coefficients, allow_pickle=False)
    tmp.replace(cached)  # a concurrent reader never sees half a file
    return coefficients


@cosine_sampled
class SpectralTabulatedBSDF(mi.BSDF):
    """The MERL-table BSDF of :mod:`abs.render.bsdfs.tabulated` for a spectral variant.

    Parameters
    ----------
    props : mi.Properties
        ``filename``: a MERL ``.binary`` file (required here: there is no table to set through
        ``mi.traverse``; the spectral renderer is not differentiated).

    Notes
    -----
    Same conventions as the RGB plugin: ``eval`` returns f · cos θo, cosine-weighted sampling,
    flags ``DiffuseReflection | FrontSide``.
    """

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        if "filename" not in props:
            raise ValueError(f"{PLUGIN_NAME} (spectral): a 'filename' is required")
        path = Path(str(mi.file_resolver().resolve(str(props["filename"]))))
        self.filename = str(path)
        self.coefficients = from_numpy(mi.Float, _cached_coefficients(path).reshape(-1))
        dr.make_opaque(self.coefficients)
        flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [flags]
        self.m_flags = flags

    def _entry(self, index: mi.UInt32, wavelengths, active: mi.Bool):
        """The spectrum of table entry ``index`` at ``wavelengths`` (1/sr)."""
        c = [dr.gather(mi.Float, self.coefficients, index * _COEFFS + k, active) for k in range(_COEFFS)]
        return mi.srgb_model_eval(mi.Vector3f(c[0], c[1], c[2]), wavelengths) * c[3]

    def _lookup(self, si: mi.SurfaceInteraction3f, wo: mi.Vector3f, active: mi.Bool):
        # The RGB plugin's coordinates and weights; only the entries' values differ (spectra).
        value = mi.Spectrum(0.0)
        for index, weight in table_corners(si.wi, wo):
            value += weight * self._entry(index, si.wavelengths, active)
        return value

    def to_string(self) -> str:
        return f"SpectralTabulatedBSDF[table={self.filename}]"


def register() -> None:
    """Register ``abs_tabulated`` for the active (spectral) variant."""
    mi.register_bsdf(PLUGIN_NAME, lambda props: SpectralTabulatedBSDF(props))
