"""Dr.Jit helpers shared by the renderer bridge."""

from __future__ import annotations

import drjit as dr
import numpy as np

__all__ = ["opaque"]


def opaque(array_type, *value):
    """``array_type(value)`` stored in memory rather than as a kernel literal.

    Values that change between renders (camera matrices, parameter values) must be opaque, or
    every new value compiles new kernels.
    """
    value = [v.astype(np.float32) if isinstance(v, np.ndarray) and v.dtype.kind == "f" else v
             for v in value]
    x = array_type(*value)
    dr.make_opaque(x)
    return x
