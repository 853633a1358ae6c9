"""abs: differentiable analysis by synthesis.

One scene representation (:mod:`abs.scene`), compiled to Mitsuba 3's differentiable renderer
(:mod:`abs.render`), fed by calibrated captures (:mod:`abs.io`). Importing ``abs`` does not start
Mitsuba; importing :mod:`abs.render` activates a variant (see :func:`abs.render.variant.set_variant`).
"""

from abs.errors import CaptureError, DeviceError, InputError, SceneError
from abs.scene import load_scene

__version__ = "0.1.0"
__all__ = ["load_scene", "fit", "scan", "FitSettings", "sample", "SampleSettings", "edit",
           "InputError",
           "SceneError", "CaptureError", "DeviceError", "__version__"]

_LAZY = {"fit": "abs.fitting", "scan": "abs.fitting", "FitSettings": "abs.fitting",
         "sample": "abs.sampling", "SampleSettings": "abs.sampling",
         # abs.resynthesis re-exports abs.editing.edit with the synthesis method registered.
         "edit": "abs.resynthesis"}


def __getattr__(name: str):
    # Fitting imports the renderer (and so starts Mitsuba): only on first use of abs.fit & co.
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'abs' has no attribute {name!r}")
