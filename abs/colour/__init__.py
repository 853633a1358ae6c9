"""Colour and light from the real set-up: spectral optical constants in RGB, colour-chart
calibration (camera RGB -> XYZ -> CIE RGB; see docs/colour.md), and the sRGB transfer functions
and tone mapping of previews (:mod:`abs.colour.srgb`, :mod:`abs.colour.tonemap`). Light probes:
:mod:`abs.probe`.

The names below are loaded on first use: the calibration modules import colour-science (about
5 s), and the sRGB and tone-mapping modules sit under every image file read (abs.io.images), which
must not pay for it.
"""

import importlib

__all__ = ["OpticalConstants", "read_refractiveindex_yaml", "optical_constants_rgb",
           "spectrum_to_rgb", "channel_centroids_m", "ColourCorrection", "calibrate",
           "read_correction", "write_correction"]

_LAZY = {"ColourCorrection": "abs.colour.correction", "calibrate": "abs.colour.correction",
         "read_correction": "abs.colour.correction_file", "write_correction": "abs.colour.correction_file",
         "OpticalConstants": "abs.colour.refractiveindex",
         "read_refractiveindex_yaml": "abs.colour.refractiveindex",
         "channel_centroids_m": "abs.colour.spectral", "optical_constants_rgb": "abs.colour.spectral",
         "spectrum_to_rgb": "abs.colour.spectral"}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'abs.colour' has no attribute {name!r}")
