"""``camera_response``: the sensor's recorded values are not proportional to radiance."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.sensor_field import SensorField


@register
class CameraResponse(SensorField):
    name = "camera_response"
    field = "response"

    def explain(self, target: str, values: dict) -> str:
        g = np.asarray(values[self.parameter], float)
        kind = "compresses highlights" if np.mean(g) < 1 else "stretches highlights"
        return (f"The sensor's response is not linear: recorded values follow radiance to the power "
                f"{g[0]:.3g}/{g[1]:.3g}/{g[2]:.3g} (R/G/B), which {kind} relative to shadows; "
                f"the scene file assumes a linear camera.")
