"""``colour_transform``: the photographs' colours are a 3x3 matrix of the rendering's, a colour
shift over the whole image (a colour calibration or white-balance error, filter cross-talk)."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.sensor_field import SensorField

_CHANNELS = "RGB"


@register
class ColourTransform(SensorField):
    name = "colour_transform"
    field = "colour_matrix"

    def explain(self, target: str, values: dict) -> str:
        m = np.asarray(values[self.parameter], float).reshape(3, 3)
        # What a user sees: a grey in the rendering comes out tinted (the row sums), and some
        # of each channel leaks into the others (the largest off-diagonal entry).
        grey = m.sum(axis=1)
        off = np.abs(m - np.diag(np.diag(m)))
        i, j = np.unravel_index(np.argmax(off), off.shape)
        return (f"A colour shift over the whole image: the photographs' colours are a 3x3 matrix "
                f"of the rendering's (a colour calibration or white-balance error), so a grey in "
                f"the rendering comes out {grey[0]:.3g}/{grey[1]:.3g}/{grey[2]:.3g} (R/G/B) times "
                f"as bright, and the largest mixing between channels is {m[i, j]:+.3g} of "
                f"{_CHANNELS[j]} in {_CHANNELS[i]}; the scene file's model assumes the "
                f"photographs are in the rendering's colour space.")
