"""``merl``: an isotropic measured BRDF from a MERL ``.binary`` table (90 x 90 x 180 x RGB)."""

from __future__ import annotations

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, register


@register
class Merl(Material):
    type_name = "merl"

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "Merl":
        fields.check_known({"type", "file"})
        self = cls(name)
        self.file = fields.file("file", suffixes=(".binary",))
        self._toml = {"type": cls.type_name, "file": str(fields.raw("file"))}
        return self

    def to_mitsuba(self) -> dict:
        return {"type": "abs_tabulated", "filename": str(self.file)}
