"""``plastic``: a diffuse base under a smooth (or GGX-rough) dielectric coating."""

from __future__ import annotations

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, ParameterSpec, register


@register
class Plastic(Material):
    type_name = "plastic"

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "Plastic":
        fields.check_known({"type", "reflectance", "ior", "roughness"})
        self = cls(name)
        self.reflectance_rgb = fields.rgb("reflectance", 0.5, lower=0.0, upper=1.0)
        self.ior = fields.number("ior", 1.49, lower=1.0, upper=3.0)
        self.roughness = fields.number("roughness", 0.0, lower=0.0, upper=1.0)
        self._toml = {"type": cls.type_name, "reflectance": self.reflectance_rgb.tolist(),
                      "ior": self.ior, "roughness": self.roughness}
        return self

    def to_mitsuba(self) -> dict:
        base = {"diffuse_reflectance": {"type": "rgb", "value": self.reflectance_rgb.tolist()},
                "int_ior": self.ior, "ext_ior": 1.0}
        if self.roughness > 0:
            return {"type": "roughplastic", "distribution": "ggx", "alpha": self.roughness, **base}
        return {"type": "plastic", **base}

    def parameters(self) -> dict[str, ParameterSpec]:
        return {"reflectance": ParameterSpec("reflectance", 3, "1", 0.0, 1.0, "diffuse_reflectance.value",
                                                 separable_channels=True)}
