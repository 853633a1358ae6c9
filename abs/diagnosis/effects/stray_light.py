"""``stray_light``: veiling glare or ambient light adds a constant offset to the photographs."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.sensor_field import SensorField


@register
class StrayLight(SensorField):
    name = "stray_light"
    field = "stray_light"

    def explain(self, target: str, values: dict) -> str:
        s = np.asarray(values[self.parameter], float)
        return (f"Stray light (veiling glare in the lens or ambient light) adds {s[0]:.3g}/"
                f"{s[1]:.3g}/{s[2]:.3g} (R/G/B, radiance units) to every pixel of the photographs, "
                f"lifting the dark parts most; the scene file's model has none.")
