"""Colour and light from the real set-up: spectral optical constants in RGB and colour-chart
calibration (camera RGB -> XYZ -> CIE RGB); see docs/colour.md. Light probes: :mod:`abs.probe`."""

from abs.colour.correction import ColourCorrection, calibrate
from abs.colour.correction_file import read_correction, write_correction
from abs.colour.refractiveindex import OpticalConstants, read_refractiveindex_yaml
from abs.colour.spectral import channel_centroids_m, optical_constants_rgb, spectrum_to_rgb

__all__ = ["OpticalConstants", "read_refractiveindex_yaml", "optical_constants_rgb",
           "spectrum_to_rgb", "channel_centroids_m", "ColourCorrection", "calibrate",
           "read_correction", "write_correction"]
