"""Dr.Jit derivatives as a JAX function, so that optimistix's solvers can drive the renderer.

The residual function ``z -> r(z)`` is a :func:`jax.pure_callback` (the renderer runs outside
JAX) with a :func:`jax.custom_jvp` whose tangent map is ``t -> J(z) @ t``, ``J`` being the
Jacobian that Dr.Jit's forward mode computed (:meth:`abs.model.problem.FitProblem.residuals`).
Because the tangent map is an explicit matrix product, JAX can linearise, transpose and batch it,
which is all that optimistix's Gauss-Newton and Levenberg-Marquardt solvers ask of a function.
Residuals and Jacobian at a point are computed once and cached, so the primal and tangent
evaluations of one linearisation cost one set of renders.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["residual_function"]

# Normal equations of 10^4-10^6 residuals lose too much in float32.
jax.config.update("jax_enable_x64", True)


def residual_function(evaluate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                      n_residuals: int, n_parameters: int):
    """Wrap ``evaluate(z) -> (r, J)`` (numpy, float64) as a differentiable JAX function of ``z``.

    Residuals are float64: abs enables JAX's 64-bit mode when this module is imported (the
    thread-local ``jax.enable_x64`` context does not reach the thread that runs callbacks).
    """
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def both(z) -> tuple[np.ndarray, np.ndarray]:
        z = np.asarray(z, np.float64)
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            r, J = evaluate(z)
            cache[key] = (np.asarray(r, np.float64), np.asarray(J, np.float64))
        return cache[key]

    r_shape = jax.ShapeDtypeStruct((n_residuals,), jnp.float64)
    j_shape = jax.ShapeDtypeStruct((n_residuals, n_parameters), jnp.float64)

    @jax.custom_jvp
    def residuals(z):
        return jax.pure_callback(lambda x: both(x)[0], r_shape, z)

    @residuals.defjvp
    def _jvp(primals, tangents):
        (z,), (t,) = primals, tangents
        r, J = jax.pure_callback(both, (r_shape, j_shape), z)
        return r, J @ t

    return residuals
