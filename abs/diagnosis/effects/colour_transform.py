"""``colour_transform``: the photographs' colours are a 3x3 matrix of the rendering's, a colour
shift over the whole image (a colour calibration or white-balance error, filter cross-talk).

The matrix's overall gain is the same image change as any fitted brightness (``environment.scale``:
``k M`` with the scale divided by ``k`` renders the same image), so a free fit drifts along that
line (measured: the diagonal ran to 5474 while the scale fell to its bound of 0). The effect
therefore adds a weak Gaussian prior that says what the effect is, a transform near the identity
(:data:`PRIOR_SD` per entry), unless the scene file already gives one; the photographs decide
everything else.
"""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.sensor_field import SensorField

_CHANNELS = "RGB"

#: Standard deviation of the prior on every entry of the matrix around the identity
#: (dimensionless): wide against a white-balance error (a 5500 K error moves the blue gain by
#: 0.16), narrow against the drift along the brightness gauge.
PRIOR_SD = 0.25


@register
class ColourTransform(SensorField):
    name = "colour_transform"
    field = "colour_matrix"

    def add(self, data: dict, target: str) -> None:
        super().add(data, target)
        priors = data.setdefault("fit", {}).setdefault("priors", {})
        priors.setdefault(self.parameter, {"mean": np.eye(3).ravel().tolist(), "sd": PRIOR_SD})

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
