"""``absorption``: Beer-Lambert absorption in glass that the scene file models as clear."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import Effect, missing, register


@register
class Absorption(Effect):
    name = "absorption"

    def targets(self, scene, compiled) -> list[str]:
        # Glass with an absorption field at its null value (clear), whatever its material type.
        return [name for name, m in scene.materials.items()
                if m.transmissive and missing(scene, compiled.specs, f"{name}.absorption")]

    def add(self, data: dict, target: str) -> None:
        data["materials"][target]["absorption"] = [0.0, 0.0, 0.0]

    def parameters(self, target: str) -> tuple[str, ...]:
        return (f"{target}.absorption",)

    def explain(self, target: str, values: dict) -> str:
        sigma = np.asarray(values[f"{target}.absorption"], float)
        transmission = 100.0 * np.exp(-sigma * 0.01)
        return (f"Light travelling through the glass '{target}' is absorbed (Beer-Lambert, "
                f"{sigma[0]:.3g}/{sigma[1]:.3g}/{sigma[2]:.3g} per metre in R/G/B, i.e. "
                f"{transmission[0]:.1f}/{transmission[1]:.1f}/{transmission[2]:.1f} % transmitted "
                f"per cm), which the scene file's clear glass leaves out; the glass looks darker "
                f"and tinted in the photographs.")
