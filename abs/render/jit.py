"""Dr.Jit helpers shared by the renderer bridge."""

from __future__ import annotations

import drjit as dr
import numpy as np

__all__ = ["from_numpy", "in_use", "opaque", "seed32"]

# Dr.Jit's LLVM backend wraps NumPy memory without copying and compiles the pointer's alignment
# into the kernel (``align 64`` when the address happens to be a multiple of 64, else
# ``align 1``). NumPy's allocations land at varying offsets, so the same kernel fed fresh arrays
# hashes differently from call to call and is compiled again (measured: 3 s of LLVM compilation
# per pose-gradient render, 97 % of a pose fit). Copies at a fixed alignment keep one kernel.
_ALIGN_BYTES = 64


def from_numpy(array_type, array, dtype=np.float32):
    """``array_type`` over a copy of ``array`` (flattened, as ``dtype``) at 64-byte alignment.

    Use for every NumPy array that enters a kernel: see the note on alignment above.
    """
    flat = np.asarray(array).ravel().astype(dtype, copy=False)
    itemsize = np.dtype(dtype).itemsize
    buffer = np.empty(flat.size + _ALIGN_BYTES // itemsize, dtype)
    start = (-buffer.ctypes.data % _ALIGN_BYTES) // itemsize
    aligned = buffer[start:start + flat.size]
    aligned[...] = flat
    return array_type(aligned)


def in_use(value) -> bool:
    """Whether a model extension's value is away from its null value of zeros or attached to the
    AD graph (a derivative at the null value needs the extension traced): the test by which
    costly extensions are skipped, bit for bit, at their null value."""
    return dr.grad_enabled(value) or bool(np.any(np.asarray(dr.detach(value)) != 0.0))


def opaque(array_type, *value):
    """``array_type(value)`` stored in memory rather than as a kernel literal.

    Values that change between renders (camera matrices, parameter values) must be opaque, or
    every new value compiles new kernels.
    """
    if len(value) == 1 and isinstance(value[0], np.ndarray) and value[0].ndim == 1:
        x = from_numpy(array_type, value[0])
    else:
        value = [v.astype(np.float32) if isinstance(v, np.ndarray) and v.dtype.kind == "f" else v
                 for v in value]
        x = array_type(*value)
    dr.make_opaque(x)
    return x


def seed32(seed: int) -> int:
    """``seed`` wrapped to the 32 bits a Mitsuba sampler takes.

    Render seeds are derived by products (call seed x view x spp batch x colour pass) and exceed
    2^32 for large call seeds; wrapping keeps them distinct for every seed a run uses."""
    return int(seed) & 0xFFFFFFFF
