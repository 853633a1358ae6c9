"""``subsurface``: light travels under the surface of a diffuse material (cloth, paper, paint)
before leaving it, which softens shadows, caustics and printed edges on it."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import Effect, missing, register


@register
class Subsurface(Effect):
    name = "subsurface"
    # The exit point spreads symmetrically around the entry point: images change to second order
    # in the spread, so the score test is blind to it.
    zero_null_derivative = True
    # A spread of a few millimetres is a fraction of a pixel once a table-top capture is
    # downsampled; it is scored and fitted on the cameras' own pixels.
    full_resolution = True

    def targets(self, scene, compiled) -> list[str]:
        used = {o.material for o in scene.objects}
        # Materials on some object with a subsurface spread at its null value (0: a surface).
        return [name for name in scene.materials
                if name in used and missing(scene, compiled.specs, f"{name}.subsurface")]

    def add(self, data: dict, target: str) -> None:
        data["materials"][target]["subsurface"] = 0.0

    def parameters(self, target: str) -> tuple[str, ...]:
        return (f"{target}.subsurface",)

    def probe(self, target: str) -> dict[str, list]:
        # A 4 mm spread: about a pixel on a table-top capture; the scan tries 1 to 16 mm.
        return {f"{target}.subsurface": [0.004]}

    def explain(self, target: str, values: dict) -> str:
        sigma_mm = 1000.0 * float(np.asarray(values[f"{target}.subsurface"], float).ravel()[0])
        return (f"Light enters the material '{target}' and leaves it about {sigma_mm:.2g} mm away "
                f"(subsurface scattering), which softens the shadows, caustics and edges seen on "
                f"it; the scene file treats it as a surface that reflects where it is lit.")
