"""``surface_roughness``: glass surfaces are not perfectly smooth, so what is seen through them
and reflected in them is blurred."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.fields import GlassField


@register
class SurfaceRoughness(GlassField):
    name = "surface_roughness"
    field = "roughness"
    null = 0.0
    # A rough interface spreads light symmetrically about the smooth direction: images change to
    # second order in the roughness, so the score test is blind to it.
    zero_null_derivative = True

    def probe(self, target: str) -> dict[str, list]:
        # Beckmann alpha 0.05: a blur of about 3 degrees, visible through a few cm of glass yet
        # small enough that a smooth truth pulls the short fit back towards 0.
        return {f"{target}.roughness": [0.05]}

    def explain(self, target: str, values: dict) -> str:
        alpha = float(np.asarray(values[f"{target}.roughness"], float).ravel()[0])
        return (f"The surfaces of the glass '{target}' are not optically smooth: their microfacet "
                f"slopes spread by about {np.degrees(np.arctan(alpha)):.2g} degrees (Beckmann "
                f"alpha {alpha:.3g}), which blurs what is seen through and reflected in it; the "
                f"scene file models a perfectly polished surface.")
