"""Shared bases of the effects that are one field of a glass material or of ``[environment]``:
the effect is missing where the field sits at its null value and is not fitted, and adding it
writes that null value (``sensor_field`` is the same for ``[sensor]``)."""

from __future__ import annotations

from typing import ClassVar

from abs.diagnosis.effects.base import Effect, missing

__all__ = ["GlassField", "TableField", "EnvironmentField"]


class GlassField(Effect):
    """An effect that is one field of transmissive materials (glass), whatever their type: a
    material type with the field at a null value is a target without a change here."""

    field: ClassVar[str]
    null: ClassVar[object]

    def targets(self, scene, compiled) -> list[str]:
        return [name for name, m in scene.materials.items()
                if m.transmissive and missing(scene, compiled.specs, f"{name}.{self.field}")]

    def add(self, data: dict, target: str) -> None:
        data["materials"][target][self.field] = self.null

    def parameters(self, target: str) -> tuple[str, ...]:
        return (f"{target}.{self.field}",)


class TableField(Effect):
    """An effect that is one field of a scene-wide table (``[environment]``, ``[sensor]``),
    whose target and parameter owner is the table itself."""

    table: ClassVar[str]
    field: ClassVar[str]
    null: ClassVar[object]

    @property
    def parameter(self) -> str:
        return f"{self.table}.{self.field}"

    def targets(self, scene, compiled) -> list[str]:
        return [self.table] if missing(scene, compiled.specs, self.parameter) else []

    def add(self, data: dict, target: str) -> None:
        data.setdefault(self.table, {})[self.field] = self.null

    def parameters(self, target: str) -> tuple[str, ...]:
        return (self.parameter,)


class EnvironmentField(TableField):
    """An effect that is one field of ``[environment]``."""

    table = "environment"
