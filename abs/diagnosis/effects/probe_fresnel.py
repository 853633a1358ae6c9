"""``probe_fresnel``: the environment map is a light probe whose mirror ball's angle-dependent
reflectance was not divided out, so the light from directions the ball's rim showed (behind the
ball as the probe camera saw it) is too bright, the wide band between a few per cent too dark (a
metal's reflectance dips below its normal-incidence value before it rises at grazing), and a
little differently so per colour channel.

The model is ``environment.probe_fresnel`` ``c`` per R, G, B (``abs.render.environment``): the
map's light divided by ``1 + c (F(cos_i) / F(1) - 1)``, ``F`` the exact Fresnel reflectance of the
ball's metal (``[environment] probe_ior``, ``probe_k``; chromium's by default), ``cos_i`` the
ball's angle of incidence for each direction seen from ``[environment] probe_view``. ``c = 1``:
the ball's reflectance left in whole. The probe camera's direction is not fitted: the scene file
must give it (its default, +z of the map's frame, is only a guess), and a wrong one puts the
correction in the wrong part of the map.
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
        return (f"The environment map still carries the light probe's mirror-ball reflectance: "
                f"{100 * c[0]:.0f}/{100 * c[1]:.0f}/{100 * c[2]:.0f} % (R/G/B) of the ball's "
                f"angle-dependent Fresnel factor is left in it, so light from the directions the "
                f"ball's rim showed is too bright and the band between slightly too dark; divide "
                f"the probe photographs by the ball's Fresnel reflectance (abs probe unwrap with "
                f"the ball's optical constants, --fresnel).")
