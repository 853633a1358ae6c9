"""BRDF tables from a PCA basis in Dr.Jit: the differentiable ``brdf_pca`` material.

:class:`abs.brdf.basis.BRDFBasis` holds the basis as numpy arrays (file format, mapping, numpy
reconstruction); rendering needs the table as a Dr.Jit array attached to the AD graph of the
coefficients, which is made here, in the renderer bridge, so that :mod:`abs.brdf` stays numpy
and below :mod:`abs.render` (docs/architecture.md).
"""

from __future__ import annotations

import weakref
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.jit import from_numpy

__all__ = ["table_from_coefficients", "bind_coefficients"]

# Dr.Jit copies of a basis' arrays per (basis, Mitsuba variant), built on first use and dropped
# with the basis: a basis is hundreds of megabytes, and copying it per render would dominate.
_DEVICE: dict[tuple[int, str], dict[str, Any]] = {}


def _device_arrays(basis) -> dict[str, Any]:
    """Dr.Jit copies of the arrays for the active variant, built once."""
    key = (id(basis), mi.variant())
    cached = _DEVICE.get(key)
    if cached is None:
        eps = basis.epsilon
        w = basis.cosine_weight.astype(np.float64)
        # Precompute the unmap's affine terms: f = offset·exp(x)·inv_w − eps·inv_w.
        cached = {
            "mean": from_numpy(mi.Float, basis.mean),
            "components": [from_numpy(mi.Float, row) for row in basis.components],
            "scale": from_numpy(mi.Float, (basis.median * w + eps) / w),
            "shift": from_numpy(mi.Float, eps / w),
        }
        _DEVICE[key] = cached
        # id() may be reused once the basis is gone: forget its arrays with it.
        weakref.finalize(basis, _DEVICE.pop, key, None)
    return cached


def table_from_coefficients(basis, coefficients: Any) -> Any:
    """BRDF table unmap(mean + componentsᵀ·c), differentiable with respect to ``c``.

    Parameters
    ----------
    basis : abs.brdf.basis.BRDFBasis
        The basis.
    coefficients : mi.Float
        K coefficients (dimensionless). Gradients flow back to them through Dr.Jit's AD.

    Returns
    -------
    mi.Float
        N = 3·90·90·180 BRDF values in 1/sr, MERL order, clamped at 0 (so entries whose
        reconstruction is negative have zero gradient).
    """
    arrays = _device_arrays(basis)
    coefficients = mi.Float(coefficients)
    if dr.width(coefficients) != basis.n_components:
        raise ValueError(
            f"expected {basis.n_components} coefficients (one per component), got {dr.width(coefficients)}"
        )
    x = arrays["mean"]
    for k, row in enumerate(arrays["components"]):
        # A width-1 gather keeps c[k] attached to the AD graph (indexing would return a Python float).
        c_k = dr.gather(mi.Float, coefficients, mi.UInt32(k))
        x = dr.fma(row, c_k, x)
    return dr.maximum(arrays["scale"] * dr.exp(x) - arrays["shift"], 0.0)


def bind_coefficients(material, field: str, value, mitsuba_params) -> None:
    """Write a ``brdf_pca`` material's coefficients: its ``abs_tabulated`` BSDF's table."""
    mitsuba_params[f"{material.name}.table"] = table_from_coefficients(material.basis, value)
