"""``environment_rotation``: the environment map is turned relative to the scene about some axis
(a misoriented light probe), so highlights, reflections and what the glass refracts of the
surroundings sit in the wrong places."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.fields import EnvironmentField

_PARAMETER = "environment.orientation"


@register
class EnvironmentRotation(EnvironmentField):
    name = "environment_rotation"
    field = "orientation"
    null = [0.0, 0.0, 0.0]

    def explain(self, target: str, values: dict) -> str:
        r = np.asarray(values[_PARAMETER], float).ravel()
        angle = float(np.linalg.norm(r))
        axis = r / angle if angle > 0 else np.array([0.0, 1.0, 0.0])
        return (f"The environment map is turned by {np.degrees(angle):.2g} degrees about the axis "
                f"({axis[0]:+.2f}, {axis[1]:+.2f}, {axis[2]:+.2f}) (world frame, +y up) relative "
                f"to the scene, so its highlights, reflections and what the glass shows of the "
                f"surroundings are misplaced; the scene file's orientation of the map (to_world "
                f"and rotation) is off, as a misoriented light probe would make it.")
