"""Shared base of the effects that live in the scene's ``[sensor]`` table (vignetting, camera
response, stray light): the table always exists with null defaults, so the effect is missing
when its field is at the null value and not fitted."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from abs.diagnosis.effects.base import Effect

__all__ = ["SensorField"]


class SensorField(Effect):
    """An effect that is one field of ``[sensor]``."""

    field: ClassVar[str]

    @property
    def parameter(self) -> str:
        return f"sensor.{self.field}"

    def null(self, scene) -> np.ndarray:
        size, _, _, _, null = type(scene.sensor).FIELDS[self.field]
        return np.full(size, float(null))

    def targets(self, scene, compiled) -> list[str]:
        value = np.asarray(getattr(scene.sensor, self.field), float)
        missing = np.array_equal(value, self.null(scene)) and self.parameter not in scene.fit_parameters
        return ["sensor"] if missing else []

    def add(self, data: dict, target: str) -> None:
        size, _, _, _, null = self._spec()
        data.setdefault("sensor", {})[self.field] = [float(null)] * size

    def _spec(self):
        from abs.scene.scene import SensorSpec

        return SensorSpec.FIELDS[self.field]

    def parameters(self, target: str) -> tuple[str, ...]:
        return (self.parameter,)
