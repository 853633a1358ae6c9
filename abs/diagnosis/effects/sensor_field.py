"""Shared base of the effects that live in the scene's ``[sensor]`` table (vignetting, camera
response, stray light, colour matrix, camera misalignment): the table always exists with null
defaults, so the effect is missing when its field is at the null value and not fitted."""

from __future__ import annotations

from abs.diagnosis.effects.fields import TableField

__all__ = ["SensorField"]


class SensorField(TableField):
    """An effect that is one field of ``[sensor]``; its null value is the field's default."""

    table = "sensor"

    @property
    def null(self) -> list:
        from abs.scene.scene import SensorSpec

        return SensorSpec.null(self.field).tolist()
