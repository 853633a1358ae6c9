"""Shared base of the effects that live in the scene's ``[sensor]`` table (vignetting, camera
response, stray light): the table always exists with null defaults, so the effect is missing
when its field is at the null value and not fitted."""

from __future__ import annotations

from typing import ClassVar

from abs.diagnosis.effects.base import Effect, missing

__all__ = ["SensorField"]


class SensorField(Effect):
    """An effect that is one field of ``[sensor]``."""

    field: ClassVar[str]

    @property
    def parameter(self) -> str:
        return f"sensor.{self.field}"

    def targets(self, scene, compiled) -> list[str]:
        return ["sensor"] if missing(scene, compiled.specs, self.parameter) else []

    def add(self, data: dict, target: str) -> None:
        from abs.scene.scene import SensorSpec

        data.setdefault("sensor", {})[self.field] = SensorSpec.null(self.field).tolist()

    def parameters(self, target: str) -> tuple[str, ...]:
        return (self.parameter,)
