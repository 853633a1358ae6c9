"""``absorption``: Beer-Lambert absorption in glass that the scene file models as clear."""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import register
from abs.diagnosis.effects.fields import GlassField


@register
class Absorption(GlassField):
    name = "absorption"
    field = "absorption"
    null = [0.0, 0.0, 0.0]

    def explain(self, target: str, values: dict) -> str:
        sigma = np.asarray(values[f"{target}.absorption"], float)
        transmission = 100.0 * np.exp(-sigma * 0.01)
        return (f"Light travelling through the glass '{target}' is absorbed (Beer-Lambert, "
                f"{sigma[0]:.3g}/{sigma[1]:.3g}/{sigma[2]:.3g} per metre in R/G/B, i.e. "
                f"{transmission[0]:.1f}/{transmission[1]:.1f}/{transmission[2]:.1f} % transmitted "
                f"per cm), which the scene file's clear glass leaves out; the glass looks darker "
                f"and tinted in the photographs.")
