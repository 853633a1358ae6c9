"""Consistent material appearance across renderers, and between the renderer and the camera.

After the tool-independent virtual material appearance paper (issue 29; docs/appearance.md): a
renderer is a set of per-material-class filters, measured once on spheres of known materials in
a Cornell box (:mod:`~abs.appearance.design`, :mod:`~abs.appearance.characterise`) as α(θ),
λ(θ), ψ(θ) per class and channel (:mod:`~abs.appearance.statistics`), stored in a documented
file (:mod:`~abs.appearance.files`), and used to make an image of one renderer look as another's
would, pixel by pixel by material id and θ (:mod:`~abs.appearance.transfer`). Histogram matching
(:mod:`~abs.appearance.histogram`) is the baseline; the metric is the structured-light study's
CIEDE2000 (:mod:`~abs.appearance.score`). Second renderers are registered by name
(:mod:`~abs.appearance.renderers`): a reconfigured Mitsuba (optionally spectral, rendered in a
worker process: :mod:`~abs.appearance.spectral`) and a simulated camera. Beyond α, λ,
ψ, two optional steps reach what they cannot: the sensor step (:mod:`~abs.appearance.sensor`:
vignetting, colour matrix and response, by radiance and image position) and the normal step
(:mod:`~abs.appearance.normals`: light moved over the normal's azimuth within a θ bin).
"""

from abs.appearance.characterise import characterise, render_design
from abs.appearance.design import characterisation_design, heldout_design
from abs.appearance.files import (read_characterisation, read_geometry, write_characterisation,
                                  write_geometry)
from abs.appearance.renderers import renderer, renderer_names
from abs.appearance.sensor import Sensor, fit_sensor
from abs.appearance.statistics import Characterisation
from abs.appearance.transfer import normal_step, sensor_step, transfer

__all__ = ["Characterisation", "Sensor", "characterise", "characterisation_design", "fit_sensor",
           "heldout_design", "normal_step", "read_characterisation", "read_geometry", "render_design",
           "renderer", "renderer_names", "sensor_step", "transfer", "write_characterisation",
           "write_geometry"]
