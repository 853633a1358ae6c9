"""Dr.Jit derivatives as a JAX function, so that optimistix's solvers can drive the renderer.

The residual function ``z -> r(z)`` is a :func:`jax.pure_callback` (the renderer runs outside
JAX) with a :func:`jax.custom_jvp` whose tangent map is ``t -> J(z) @ t``, ``J`` being the
Jacobian that Dr.Jit's forward mode computed (:meth:`abs.model.problem.FitProblem.residuals`).
Because the tangent map is an explicit matrix product, JAX can linearise, transpose and batch it,
which is all that optimistix's Gauss-Newton and Levenberg-Marquardt solvers ask of a function.
Residuals and Jacobian at a point are computed once and cached, so the primal and tangent
evaluations of one linearisation cost one set of renders.

:class:`on_calling_thread` runs a solve so that these callbacks still execute on the thread that
recorded Dr.Jit's AD state.
"""

from __future__ import annotations

import queue
import threading
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["residual_function", "on_calling_thread"]

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


class on_calling_thread:
    """Run a JAX host callback on the thread that started the solve.

    XLA may run host callbacks on its own threads, but Dr.Jit's AD state is per thread (a
    forward pass started on another thread refuses the graph recorded here). So the solver runs on
    a helper thread and every callback is posted back to the calling thread, which serves them
    until the solver returns.
    """

    _requests: queue.Queue | None = None

    def __init__(self, function):
        self.function = function

    def __call__(self, *args):
        requests = type(self)._requests
        if requests is None:  # no solve in progress: a direct call
            return self.function(*args)
        reply: queue.Queue = queue.Queue(maxsize=1)
        requests.put((self.function, args, reply))
        ok, value = reply.get()
        if not ok:
            raise value
        return value

    @classmethod
    def run(cls, solve):
        cls._requests = requests = queue.Queue()
        outcome: dict = {}

        def worker():
            try:
                outcome["value"] = solve()
            except BaseException as exc:  # noqa: BLE001 (re-raised on the calling thread)
                outcome["error"] = exc
            requests.put(None)

        threading.Thread(target=worker, daemon=True, name="abs-optimistix").start()
        try:
            while (item := requests.get()) is not None:
                function, args, reply = item
                try:
                    reply.put((True, function(*args)))
                except BaseException as exc:  # noqa: BLE001 (handed to the solver thread)
                    outcome.setdefault("callback_error", exc)
                    reply.put((False, exc))
        finally:
            cls._requests = None
        if "callback_error" in outcome:
            raise outcome["callback_error"]
        if "error" in outcome:
            raise outcome["error"]
        return outcome["value"]
