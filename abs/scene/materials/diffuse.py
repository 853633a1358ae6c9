"""``diffuse``: Lambertian reflectance, a constant RGB albedo or a texture image, with optional
subsurface spread: light leaves the surface displaced from where it arrived by a Gaussian of
standard deviation ``subsurface`` metres per tangent axis (0, the default: plain Lambertian).

Texture PNGs are read as sRGB-encoded and decoded to linear RGB; EXR textures are linear.
"""

from __future__ import annotations

import numpy as np

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, ParameterSpec, register

_TEXTURES = (".png", ".jpg", ".jpeg", ".exr")
SUBSURFACE_MAX_M = 0.1  # 10 cm: far beyond any cloth or paper


def reflectance_texture(fields: Fields, key: str, default) -> tuple[np.ndarray | None, object]:
    """Read an RGB reflectance that may be a texture path. Returns ``(rgb or None, path or None)``."""
    if isinstance(fields.raw(key, default), str):
        return None, fields.file(key, suffixes=_TEXTURES)
    return fields.rgb(key, default, lower=0.0, upper=1.0), None


def texture_dict(path) -> dict:
    """A differentiable Mitsuba texture: decoded here to linear float RGB, because Mitsuba keeps
    8-bit images as ``uint8`` tensors, which cannot carry gradients."""
    import mitsuba as mi

    from abs.io.images import read_image

    return {"type": "bitmap", "bitmap": mi.Bitmap(read_image(path)), "raw": True,
            "filter_type": "bilinear"}


@register
class Diffuse(Material):
    type_name = "diffuse"

    @classmethod
    def from_fields(cls, name: str, fields: Fields) -> "Diffuse":
        fields.check_known({"type", "reflectance", "subsurface"})
        self = cls(name)
        self.reflectance_rgb, self.texture = reflectance_texture(fields, "reflectance", 0.5)
        self.subsurface_m = fields.number("subsurface", 0.0, lower=0.0, upper=SUBSURFACE_MAX_M)
        value = str(fields.raw("reflectance")) if self.texture is not None else self.reflectance_rgb.tolist()
        self._toml = {"type": cls.type_name, "reflectance": value, "subsurface": self.subsurface_m}
        return self

    def to_mitsuba(self) -> dict:
        if self.texture is not None:
            return {"type": "diffuse", "reflectance": texture_dict(self.texture)}
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": self.reflectance_rgb.tolist()}}

    def parameters(self) -> dict[str, ParameterSpec]:
        # Read by the path tracer (abs.render.integrator), not by the Mitsuba BSDF.
        subsurface = ParameterSpec("subsurface", 1, "m", 0.0, SUBSURFACE_MAX_M, None, null=0.0)
        if self.texture is not None:
            # The whole texture (H x W x 3 values) is the parameter; its size is known once loaded.
            return {"reflectance": ParameterSpec("reflectance", -1, "1", 0.0, 1.0, "reflectance.data"),
                    "subsurface": subsurface}
        return {"reflectance": ParameterSpec("reflectance", 3, "1", 0.0, 1.0, "reflectance.value",
                                             separable_channels=True),
                "subsurface": subsurface}

    def apply(self, field: str, value, mitsuba_params) -> None:
        """``subsurface`` has no Mitsuba counterpart: the compiled scene hands it to the tracer."""
        if field != "subsurface":
            super().apply(field, value, mitsuba_params)
