"""``roughdielectric``: glass with GGX-rough surfaces (Mitsuba's ``roughdielectric``; one IOR for
all channels, differentiable at moderate roughness, see shared/docs/mitsuba-facts.md)."""

from __future__ import annotations

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, ParameterSpec, register


@register
class RoughDielectric(Material):
    type_name = "roughdielectric"
    transmissive = True

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "RoughDielectric":
        fields.check_known({"type", "ior", "roughness"})
        self = cls(name)
        self.ior = fields.number("ior", 1.5, lower=1.0, upper=3.0)
        self.roughness = fields.number("roughness", 0.1, lower=1e-3, upper=1.0)
        self._toml = {"type": cls.type_name, "ior": self.ior, "roughness": self.roughness}
        return self

    def to_mitsuba(self) -> dict:
        return {"type": "roughdielectric", "distribution": "ggx", "alpha": self.roughness,
                "int_ior": self.ior, "ext_ior": 1.0}

    def parameters(self) -> dict[str, ParameterSpec]:
        return {
            "ior": ParameterSpec("ior", 1, "1", 1.0, 3.0, "eta", moves_paths=True),
            "roughness": ParameterSpec("roughness", 1, "1", 1e-3, 1.0, "alpha.value", moves_paths=True),
        }
