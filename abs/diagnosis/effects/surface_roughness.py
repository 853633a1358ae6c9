"""``surface_roughness``: glass surfaces are not perfectly smooth, so what is seen through them
and reflected in them is blurred."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import Effect, missing, register


@register
class SurfaceRoughness(Effect):
    name = "surface_roughness"
    # A rough interface spreads light symmetrically about the smooth direction: images change to
    # second order in the roughness, so the score test is blind to it.
    zero_null_derivative = True

    def targets(self, scene, compiled) -> list[str]:
        # Glass whose roughness can be, and is, 0 (roughdielectric's cannot: it has no null).
        return [name for name, m in scene.materials.items()
                if m.transmissive and missing(scene, compiled.specs, f"{name}.roughness")]

    def add(self, data: dict, target: str) -> None:
        data["materials"][target]["roughness"] = 0.0

    def parameters(self, target: str) -> tuple[str, ...]:
        return (f"{target}.roughness",)

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
