"""``env_distance``: the environment is at a finite distance, so its light shows parallax."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.fields import EnvironmentField

_PARAMETER = "environment.inverse_distance"


@register
class EnvironmentDistance(EnvironmentField):
    name = "env_distance"
    field = "inverse_distance"
    null = 0.0

    def explain(self, target: str, values: dict) -> str:
        inv = float(np.asarray(values[_PARAMETER], float).ravel()[0])
        distance = f"about {1.0 / inv:.3g} m" if inv > 0 else "very far"
        return (f"The surroundings are not infinitely far away but {distance} from the scene "
                f"(1/distance = {inv:.3g} per metre), so what the glass and the cameras see of "
                f"them shifts with viewpoint (parallax); the scene file puts them at infinity.")
