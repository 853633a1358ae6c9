"""``conductor``: a metal with per-channel complex IOR ``eta + i k``, optionally rough
(GGX microfacets, ``roughness`` = alpha)."""

from __future__ import annotations

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, ParameterSpec, register


@register
class Conductor(Material):
    type_name = "conductor"

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "Conductor":
        fields.check_known({"type", "eta", "k", "roughness"})
        self = cls(name)
        # Defaults: chromium at R, G, B (refractiveindex.info, Johnson & Christy, ~0.61/0.53/0.47 um).
        self.eta_rgb = fields.rgb("eta", [3.2, 2.7, 2.3], lower=0.0)
        self.k_rgb = fields.rgb("k", [3.3, 3.2, 3.1], lower=0.0)
        self.roughness = fields.number("roughness", 0.0, lower=0.0, upper=1.0)
        self._toml = {"type": cls.type_name, "eta": self.eta_rgb.tolist(), "k": self.k_rgb.tolist(),
                      "roughness": self.roughness}
        return self

    def to_mitsuba(self) -> dict:
        spectra = {"eta": {"type": "rgb", "value": self.eta_rgb.tolist()},
                   "k": {"type": "rgb", "value": self.k_rgb.tolist()}}
        if self.roughness > 0:
            return {"type": "roughconductor", "distribution": "ggx", "alpha": self.roughness, **spectra}
        return {"type": "conductor", **spectra}

    def parameters(self) -> dict[str, ParameterSpec]:
        specs = {
            "eta": ParameterSpec("eta", 3, "1", 0.0, 20.0, "eta.value", separable_channels=True),
            "k": ParameterSpec("k", 3, "1", 0.0, 20.0, "k.value", separable_channels=True),
        }
        if self.roughness > 0:
            specs["roughness"] = ParameterSpec("roughness", 1, "1", 1e-3, 1.0, "alpha.value",
                                               moves_paths=True)
        return specs
