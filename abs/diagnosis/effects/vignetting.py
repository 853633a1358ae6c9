"""``vignetting``: the camera's radial falloff of brightness towards the image corners."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.sensor_field import SensorField


@register
class Vignetting(SensorField):
    name = "vignetting"
    field = "vignetting"

    def explain(self, target: str, values: dict) -> str:
        k1, k2 = np.asarray(values[self.parameter], float)
        r2 = np.tan(np.radians(15.0)) ** 2
        factor = 1.0 + k1 * r2 + k2 * r2 ** 2
        return (f"The camera darkens the image towards its corners (vignetting: brightness times "
                f"1 + k1 r^2 + k2 r^4 with k1 = {k1:.3g}, k2 = {k2:.3g}, r the off-axis distance "
                f"over the focal length), {100 * (1 - factor):.1f} % darker 15 degrees off-axis; "
                f"the scene file's ideal camera has none.")
