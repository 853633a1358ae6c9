"""``probe_fresnel``: the environment map is a light probe whose chrome ball's angle-dependent
reflectance was not divided out, so the light from directions the ball's rim showed (behind the
ball as the probe camera saw it) is too bright, and a little differently so per colour channel.

The model is ``environment.probe_fresnel`` ``c`` per R, G, B (``abs.render.environment``): the
map's light divided by Schlick's ``1 + c (1 - cos_i)^5``, ``cos_i`` the ball's angle of
incidence for each direction seen from ``[environment] probe_view``. Chromium's ``c = 1/F0 - 1``
is about 0.8. The probe camera's direction is not fitted: the scene file must give it (its
default, +z of the map's frame, is only a guess), and a wrong one puts the correction in the
wrong part of the map. The part of the map it changes (within about 50 degrees of the direction
opposite the probe camera) lights the scene only where the scene sees it.
"""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.fields import EnvironmentField

_PARAMETER = "environment.probe_fresnel"


@register
class ProbeFresnel(EnvironmentField):
    name = "probe_fresnel"
    field = "probe_fresnel"
    null = [0.0, 0.0, 0.0]

    def explain(self, target: str, values: dict) -> str:
        c = np.asarray(values[_PARAMETER], float).ravel()
        grazing = 1.0 + c  # the map's excess at the ball's rim (cos_i = 0)
        return (f"The environment map still carries the light probe's chrome reflectance: light "
                f"from the directions the ball's rim showed is {grazing[0]:.3g}/{grazing[1]:.3g}/"
                f"{grazing[2]:.3g} (R/G/B) times too bright in the map relative to what faced the "
                f"probe camera (a metal with normal-incidence reflectance about "
                f"{1 / grazing.mean():.2g}); divide the probe photographs by the ball's Fresnel "
                f"reflectance (abs probe unwrap with the ball's optical constants).")
