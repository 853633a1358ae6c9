"""``diffuse``: Lambertian reflectance, a constant RGB albedo or a texture image, with optional
subsurface spread: light leaves the surface displaced from where it arrived by a Gaussian of
standard deviation ``subsurface`` metres per tangent axis (0, the default: plain Lambertian), and
an optional anisotropic lobe of woven threads: ``anisotropy = [warp, weft]``, the fractions of the
reflected light that leave by the warp's and the weft's lobes (``[0, 0]``, the default: plain
Lambertian), the warp along ``thread_direction`` (world frame, projected onto the surface; the
weft across it) with GGX roughness ``thread_roughness = [along, across]`` a thread. The model and
why it is exactly Lambertian at ``[0, 0]``: :mod:`abs.render.bsdfs.diffuse`.

Texture PNGs are read as sRGB-encoded and decoded to linear RGB; EXR textures are linear.
"""

from __future__ import annotations

import numpy as np

from abs.scene.fields import Fields
from abs.scene.materials.base import Material, ParameterSpec, register

_TEXTURES = (".png", ".jpg", ".jpeg", ".exr")
SUBSURFACE_MAX_M = 0.1  # 10 cm: far beyond any cloth or paper
# Each lobe's weight at most 1/2, so that the Lambertian's, 1 - warp - weft, stays >= 0.
ANISOTROPY_MAX = 0.5
# GGX alphas of a thread: below 0.05 a lobe is a mirror that cosine sampling cannot resolve; 1 is
# a cylinder's spread of normals across it (+-90 degrees).
THREAD_ROUGHNESS = (0.05, 1.0)


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
        fields.check_known({"type", "reflectance", "subsurface", "anisotropy", "thread_direction",
                            "thread_roughness"})
        self = cls(name)
        self.reflectance_rgb, self.texture = reflectance_texture(fields, "reflectance", 0.5)
        self.subsurface_m = fields.number("subsurface", 0.0, lower=0.0, upper=SUBSURFACE_MAX_M)
        self.anisotropy = fields.vector("anisotropy", 2, 0.0, lower=0.0, upper=ANISOTROPY_MAX)
        direction = fields.vector("thread_direction", 3, [1.0, 0.0, 0.0])
        if not np.linalg.norm(direction) > 1e-9:
            raise fields.error("thread_direction", f"must not be zero, got {direction.tolist()}")
        self.thread_direction = direction / np.linalg.norm(direction)
        self.thread_roughness = fields.vector("thread_roughness", 2, [0.3, 1.0],
                                              lower=THREAD_ROUGHNESS[0], upper=THREAD_ROUGHNESS[1])
        # A material whose file names none of the threads' fields is plain Lambertian and compiles
        # to Mitsuba's own diffuse: scenes without woven cloth render (and are rendered by plain
        # Mitsuba, e.g. the glass benchmark's independent photographs) without abs's plugin.
        self.threads = any(fields.has(k) for k in ("anisotropy", "thread_direction",
                                                   "thread_roughness"))
        value = str(fields.raw("reflectance")) if self.texture is not None else self.reflectance_rgb.tolist()
        self._toml = {"type": cls.type_name, "reflectance": value, "subsurface": self.subsurface_m}
        if self.threads:
            self._toml.update({"anisotropy": self.anisotropy.tolist(),
                               "thread_direction": self.thread_direction.tolist(),
                               "thread_roughness": self.thread_roughness.tolist()})
        return self

    def to_mitsuba(self) -> dict:
        import mitsuba as mi

        reflectance = (texture_dict(self.texture) if self.texture is not None
                       else {"type": "rgb", "value": self.reflectance_rgb.tolist()})
        if not self.threads:
            return {"type": "diffuse", "reflectance": reflectance}
        # With threads, abs's plugin at every value, the null one included: the anisotropy
        # parameter must exist in the compiled scene wherever a fit may release it (it is
        # Mitsuba's diffuse there).
        return {"type": "abs_diffuse", "reflectance": reflectance,
                "anisotropy_warp": float(self.anisotropy[0]), "anisotropy_weft": float(self.anisotropy[1]),
                "thread_direction": mi.ScalarVector3f(*map(float, self.thread_direction)),
                "thread_along": float(self.thread_roughness[0]),
                "thread_across": float(self.thread_roughness[1])}

    def parameters(self) -> dict[str, ParameterSpec]:
        # Read by the path tracer (abs.render.integrator), not by the Mitsuba BSDF.
        extensions = {
            "subsurface": ParameterSpec("subsurface", 1, "m", 0.0, SUBSURFACE_MAX_M, None, null=0.0)}
        if self.threads:
            # Weights of the threads' lobes ([warp, weft]); [0, 0]: plain Lambertian. They
            # reweight the BSDF's samples only (its sampling does not depend on them). No
            # typical_step: with both bounds finite it sets the sigmoid's gain from the start,
            # and a start on the lower bound (the null value) made the gain about 1000, a step
            # function between 0 and 0.5 (a diagnosis's fit jumped to 0.45 for a true 0.3).
            extensions["anisotropy"] = ParameterSpec("anisotropy", 2, "1", 0.0, ANISOTROPY_MAX,
                                                     "anisotropy", null=0.0)
        if self.texture is not None:
            # The whole texture (H x W x 3 values) is the parameter; its size is known once loaded.
            return {"reflectance": ParameterSpec("reflectance", -1, "1", 0.0, 1.0, "reflectance.data"),
                    **extensions}
        return {"reflectance": ParameterSpec("reflectance", 3, "1", 0.0, 1.0, "reflectance.value",
                                             separable_channels=True),
                **extensions}

    def apply(self, field: str, value, mitsuba_params) -> None:
        """``subsurface`` has no Mitsuba counterpart: the compiled scene hands it to the tracer."""
        if field != "subsurface":
            super().apply(field, value, mitsuba_params)
