"""Renderers to characterise, registered by name: abs's own and the "second renderers".

A renderer turns a design scene (:class:`abs.appearance.design.SceneSpec`), an environment map
and a camera into a linear RGB image. Each is one class registered with :func:`register`; its
options (``--option key=value`` on the command line) are checked against its ``defaults``.

- ``abs``: abs's path tracer (:class:`abs.render.PathTracer`), the reference.
- ``mitsuba``: stock Mitsuba configured differently, the way another tool differs from abs: the
  ``path`` integrator at a low ``max_depth``, GGX ``alpha = roughness²`` where abs uses
  ``alpha = roughness``, thin instead of solid glass, and a white-balance and exposure offset;
  with ``spectral=true``, rendered in a spectral variant (in a worker process).
- ``camera``: abs's rendering seen through a simulated camera (vignetting, a colour matrix, a
  compressive response curve with a black level); the characterisation knows nothing of these
  parameters, it only sees the images.
- ``gains``: abs's rendering times known per-channel gains, a synthetic filter whose gains a
  characterisation must recover.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import mitsuba as mi
import numpy as np

from abs.appearance.scenes import scene_dict
from abs.appearance.spectral import render_spectral, stock_glass_ior
from abs.errors import InputError
from abs.render.bsdfs import tabulated as _tabulated  # noqa: F401  (registers abs_tabulated)
from abs.render.camera import Camera
from abs.render.environment import Environment
from abs.render.integrator import PathTracer
from abs.render.medium_truth import mitsuba_sensor

__all__ = ["Renderer", "register", "renderer", "renderer_names"]

_REGISTRY: dict[str, type["Renderer"]] = {}


class Renderer(ABC):
    """A renderer to characterise.

    Parameters
    ----------
    options : dict
        Overrides of :attr:`defaults` (same keys).
    """

    name: ClassVar[str]
    defaults: ClassVar[dict] = {}

    def __init__(self, options: dict | None = None):
        options = dict(options or {})
        unknown = sorted(set(options) - set(self.defaults))
        if unknown:
            raise InputError(None, f"--option {unknown[0]}",
                             f"renderer {self.name!r} has no such option; expected one of "
                             f"{sorted(self.defaults)}")
        self.options = {**self.defaults, **options}

    @abstractmethod
    def render(self, spec, environment: np.ndarray, camera: Camera, spp: int,
               seed: int) -> np.ndarray:
        """``(height, width, 3)`` float32 linear RGB of ``spec`` under ``environment`` (lat-long)."""


def register(cls: type[Renderer]) -> type[Renderer]:
    """Class decorator: make a renderer available under ``cls.name``."""
    _REGISTRY[cls.name] = cls
    return cls


def renderer_names() -> list[str]:
    return sorted(_REGISTRY)


def renderer(name: str, options: dict | None = None) -> Renderer:
    """The registered renderer ``name`` with ``options``; an unknown name is an InputError."""
    if name not in _REGISTRY:
        raise InputError(None, "--renderer", f"unknown renderer {name!r}; expected one of "
                                             f"{renderer_names()}")
    return _REGISTRY[name](options)


def _abs_render(spec, environment, camera, spp, seed, max_depth) -> np.ndarray:
    scene = mi.load_dict(scene_dict(spec))
    image = PathTracer(max_depth=int(max_depth)).render(scene, Environment(environment), camera,
                                                        spp, seed=seed)
    return np.asarray(image, np.float32)


@register
class AbsRenderer(Renderer):
    name = "abs"
    defaults = {"max_depth": 8}

    def render(self, spec, environment, camera, spp, seed):
        return _abs_render(spec, environment, camera, spp, seed, self.options["max_depth"])


def _reconfigure_bsdf(bsdf: dict, squared_roughness: bool, thin_glass: bool) -> dict:
    """A BSDF as the other tool reads the same material fields."""
    bsdf = dict(bsdf)
    if squared_roughness and "alpha" in bsdf:
        # abs: alpha = roughness; many tools: alpha = roughness² (a "perceptual" roughness).
        bsdf["alpha"] = float(bsdf["alpha"]) ** 2
    if thin_glass and bsdf["type"] in ("dielectric", "roughdielectric"):
        bsdf = {"type": "thindielectric", "int_ior": bsdf["int_ior"], "ext_ior": bsdf["ext_ior"],
                **({"id": bsdf["id"]} if "id" in bsdf else {})}
    elif thin_glass and bsdf["type"] == "abs_dielectric":
        # abs's smooth glass (its scene type "dielectric" compiles to abs's own plugin): the
        # other tool's thin sheet of the same IOR. Only clear, non-dispersive glass has one.
        ior = stock_glass_ior(bsdf)
        if ior is not None:
            bsdf = {"type": "thindielectric", "int_ior": ior, "ext_ior": 1.0,
                    **({"id": bsdf["id"]} if "id" in bsdf else {})}
    return bsdf


@register
class MitsubaRenderer(Renderer):
    """Stock Mitsuba, reconfigured; ``spectral=true`` renders in a spectral variant.

    Spectral rendering is an option of this renderer rather than a renderer of its own because
    it is one more setting of the same tool, and it composes with the others: ``spectral=true``
    alone with the other options at abs's values isolates it, with the defaults it is the
    reconfigured Mitsuba rendered spectrally. It runs in a worker process
    (:mod:`abs.appearance.spectral`), since abs's process holds ``llvm_ad_rgb``;
    ``spectral_variant`` names the variant (``llvm_ad_spectral``). The MERL-table class keeps
    its table, upsampled per entry (:mod:`abs.appearance.spectral_tabulated`).
    """

    name = "mitsuba"
    defaults = {"max_depth": 3, "squared_roughness": True, "thin_glass": True,
                "white_balance": [1.12, 1.0, 0.86], "exposure": 0.8, "spectral": False,
                "spectral_variant": "llvm_ad_spectral"}

    def render(self, spec, environment, camera, spp, seed):
        o = self.options
        d = scene_dict(spec)
        for key, value in d.items():
            if isinstance(value, dict) and "bsdf" in value and key.startswith("object"):
                value["bsdf"] = _reconfigure_bsdf(value["bsdf"], bool(o["squared_roughness"]),
                                                  bool(o["thin_glass"]))
        d["integrator"] = {"type": "path", "max_depth": int(o["max_depth"])}
        d["sensor"] = mitsuba_sensor(camera)
        if not isinstance(o["spectral"], bool):
            raise InputError(None, "--option spectral", f"renderer {self.name!r}: expected true "
                                                        f"or false, got {o['spectral']!r}")
        if o["spectral"]:
            image = render_spectral(d, environment, spp, seed, variant=str(o["spectral_variant"]),
                                    field=f"renderer {self.name!r} --option spectral=true")
        else:
            d["emitter"] = {"type": "envmap",
                            "bitmap": mi.Bitmap(np.asarray(environment, np.float32))}
            image = np.asarray(mi.render(mi.load_dict(d), spp=spp, seed=seed), np.float32)
        gains = np.asarray(o["white_balance"], np.float32) * np.float32(o["exposure"])
        return image[..., :3] * gains


def camera_response(x: np.ndarray, knee: float, power: float, black: float) -> np.ndarray:
    """A compressive sensor response: ``black + (1 + knee) y / (y + knee)``, ``y = x**power``.

    Linear-ish for small ``x``, saturating towards ``black + 1 + knee``.
    """
    y = np.maximum(x, 0.0) ** power
    return black + (1.0 + knee) * y / (y + knee)


@register
class CameraRenderer(Renderer):
    name = "camera"
    # The "unknown" camera: the characterisation never reads these, it only sees the images.
    defaults = {"max_depth": 8, "vignetting": 0.25, "knee": 1.5, "power": 0.9, "black": 0.004,
                "colour_matrix": [[0.86, 0.12, 0.02], [0.06, 0.84, 0.10], [0.01, 0.14, 0.85]]}

    def render(self, spec, environment, camera, spp, seed):
        o = self.options
        image = _abs_render(spec, environment, camera, spp, seed, o["max_depth"])
        h, w = image.shape[:2]
        v, u = np.mgrid[0:h, 0:w]
        r2 = (((u - camera.K[0, 2]) ** 2 + (v - camera.K[1, 2]) ** 2)
              / (camera.K[0, 2] ** 2 + camera.K[1, 2] ** 2))
        image = image * (1.0 - float(o["vignetting"]) * r2)[..., None]
        image = image @ np.asarray(o["colour_matrix"], np.float64).T
        out = camera_response(image, float(o["knee"]), float(o["power"]), float(o["black"]))
        return out.astype(np.float32)


@register
class GainsRenderer(Renderer):
    name = "gains"
    defaults = {"max_depth": 8, "gains": [1.0, 1.0, 1.0]}

    def render(self, spec, environment, camera, spp, seed):
        image = _abs_render(spec, environment, camera, spp, seed, self.options["max_depth"])
        return (image * np.asarray(self.options["gains"], np.float32)).astype(np.float32)
