"""The renderer bridge: abs scenes compiled to Mitsuba 3 / Dr.Jit, rendered and differentiated.

Importing this package activates a Mitsuba variant (see :mod:`abs.render.variant`) unless one is
active already: call :func:`abs.set_variant` first to choose another. abs's Mitsuba plugins are
bound to the variant active when they are registered.
"""

from abs.render.variant import current_variant, set_variant

if current_variant() is None:
    set_variant()

from abs.render.camera import Camera  # noqa: E402
from abs.render.compiled import CompiledScene, compile_scene  # noqa: E402
from abs.render.environment import Environment  # noqa: E402
from abs.render.integrator import PathTracer  # noqa: E402

__all__ = ["Camera", "CompiledScene", "compile_scene", "Environment", "PathTracer", "set_variant"]
