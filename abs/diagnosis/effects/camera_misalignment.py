"""``camera_misalignment``: the photographs' camera matrix is not the calibrated one (a principal
point or focal length off by a pixel or so, or every camera turned by the same small angle), so
the image of the scene is shifted or scaled against the rendering and the residual lines up along
edges (the checkerboard's, the objects' outlines).

The model is ``[sensor] intrinsics_offset`` (``abs.render.sensor``): the rendering resampled as
the photographs' camera sees it, exact for a pinhole. A principal-point shift of ``dc`` pixels is,
to first order, a turn of every camera by ``dc / f`` radians about its centre, so this effect
also names a common small rotation of the cameras; it cannot model a different error per view or
a translation of a camera (parallax).
"""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.sensor_field import SensorField


@register
class CameraMisalignment(SensorField):
    name = "camera_misalignment"
    field = "intrinsics_offset"

    def explain(self, target: str, values: dict) -> str:
        dcx, dcy, dfx = np.asarray(values[self.parameter], float).ravel()
        return (f"The photographs' camera is not the calibrated one: the image sits "
                f"{dcx:+.2f}/{dcy:+.2f} pixels (x/y, full resolution) from where the calibration "
                f"puts it and its focal length differs by {dfx:+.2f} pixels, so edges and "
                f"outlines are misplaced; a principal-point or focal-length error of the "
                f"calibration, or every camera turned by the same small angle (a shift of "
                f"f x angle pixels).")
