"""The two optimisers of a fit, over the unconstrained vector ``z`` (see ``parameters.py``).

- :func:`levenberg_marquardt`: optimistix's Levenberg-Marquardt on the residual vector, with the
  renderer's forward-mode Jacobian (``jax_bridge.py``). Second order: few iterations, each
  costing about ``1 + P`` renders per view; the choice when the parameter count ``P`` is small.
- :func:`gauss_newton_refinement`: after Levenberg-Marquardt, a few Gauss-Newton steps whose
  residuals and Jacobian come from independent renders with fresh seeds. Levenberg-Marquardt
  minimises the squared residual of one fixed noisy render (common random numbers: a smooth,
  deterministic objective), whose expectation adds the render variance; that variance depends on
  the parameters (a brighter scene is noisier), which pulls the minimum towards darker
  renderings. The refinement's fixed point, ``E[J_B^T r_A] = 0``, has no such bias; its
  curvature comes from two independent Jacobians (:func:`cross_curvature`) so the steps are not
  shortened by the Jacobian noise; its steps grow while they keep pointing the same way (the
  unbiased solution can be many typical steps away); its iterates that have arrived are averaged,
  and their scatter is the Monte-Carlo part of the standard errors.
- :func:`adam`: Adam on stochastic gradients (a new render seed per iteration), with spp and
  resolution schedules; the choice for many scalars. The result is the average of the last
  quarter of the iterates, which cancels most of the Monte-Carlo jitter of the final steps.

Both report every iteration to ``on_iteration`` (progress, checkpoints: kept out of here) and can
start from a saved :class:`OptimizerState`.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass, field
from typing import Callable

import jax.numpy as jnp
import numpy as np
import optimistix as optx

from abs.fitting.jax_bridge import residual_function

__all__ = ["OptimizerState", "levenberg_marquardt", "gauss_newton_refinement", "cross_curvature",
           "averaged_refinement_points", "adam"]


@dataclass
class OptimizerState:
    """Where an optimisation stands (JSON-serialisable through :meth:`to_dict`).

    Attributes
    ----------
    method : str
        ``"lm"`` or ``"adam"``.
    iteration : int
        Iterations done.
    z : ndarray
        Current unconstrained parameters (LM: the last accepted point).
    history : list of dict
        One entry per iteration: ``iteration``, ``loss`` (RMSE of the residuals), ``z``.
    moments : dict
        Adam's first and second moments (``m``, ``v``) and its iterate sum for averaging.
    """

    method: str
    iteration: int
    z: np.ndarray
    history: list[dict] = field(default_factory=list)
    moments: dict[str, list] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"method": self.method, "iteration": self.iteration, "z": list(map(float, self.z)),
                "history": self.history, "moments": self.moments}

    @classmethod
    def from_dict(cls, d: dict) -> "OptimizerState":
        return cls(str(d["method"]), int(d["iteration"]), np.asarray(d["z"], np.float64),
                   list(d.get("history", [])), dict(d.get("moments", {})))


Callback = Callable[[OptimizerState], None]


class _on_calling_thread:
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


def levenberg_marquardt(evaluate: Callable[[np.ndarray, int], tuple[np.ndarray, np.ndarray, float]],
                        state: OptimizerState, n_residuals: int, max_iterations: int,
                        rtol: float = 1e-4, atol: float = 1e-6,
                        on_iteration: Callback | None = None) -> OptimizerState:
    """Minimise ``|r(z)|^2`` with optimistix's Levenberg-Marquardt.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(z, iteration) -> (r, J, loss)``: residuals (M,), their Jacobian (M, P) w.r.t.
        ``z``, and the loss to report (the RMSE of the pixel residuals).
    state : OptimizerState
        Start (a resumed run restarts the damping at its last accepted point).
    rtol, atol : float
        optimistix's Cauchy termination on steps in ``z`` and on the residual norm.
    """
    remaining = max_iterations - state.iteration
    if remaining <= 0:
        return state
    n = state.z.size
    # optimistix evaluates at the trial point and accepts or rejects it afterwards, so the
    # accepted point is tracked as the best so far (LM never accepts an increase).
    best = {"loss": np.inf, "z": state.z.copy()}
    if state.history:
        best["loss"] = min(h["loss"] for h in state.history)

    def counted(z):
        state.iteration += 1
        r, J, loss = evaluate(z, state.iteration)
        if loss < best["loss"]:
            best.update(loss=loss, z=np.array(z))
        state.z = best["z"]
        state.history.append({"iteration": state.iteration, "loss": loss,
                              "z": list(map(float, z))})
        if on_iteration is not None:
            on_iteration(state)
        return r, J

    fn = residual_function(_on_calling_thread(counted), n_residuals, n)
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    solution = _on_calling_thread.run(
        lambda: optx.least_squares(lambda z, args: fn(z), solver, jnp.asarray(state.z, jnp.float64),
                                   max_steps=remaining, throw=False))
    final = np.asarray(solution.value, np.float64)
    state.moments["lm_converged"] = bool(solution.result == optx.RESULTS.successful)
    # The solver's accepted point is its answer; it equals the best evaluated point unless the
    # last trial was rejected, in which case both are the same accepted point.
    state.z = final if np.all(np.isfinite(final)) else best["z"]
    return state


def cross_curvature(J1: np.ndarray, J2: np.ndarray) -> np.ndarray:
    """Unbiased estimate of ``J^T J`` from two independent noisy Jacobians, made positive definite.

    ``E[J1^T J1] = Jbar^T Jbar + Cov`` overstates the curvature by the Jacobian's Monte-Carlo
    covariance; ``(J1^T J2 + J2^T J1) / 2`` has expectation ``Jbar^T Jbar`` exactly. Its noise can
    make small eigenvalues negative: they are raised to 1e-3 of the largest (such directions are
    then limited by the step clip, not thrown far).
    """
    H = 0.5 * (J1.T @ J2 + J2.T @ J1)
    w, V = np.linalg.eigh(H)
    w = np.maximum(w, 1e-3 * max(float(w.max()), 1e-300))
    return (V * w) @ V.T


def averaged_refinement_points(points: list, travelling: list | None = None) -> np.ndarray:
    """The refinement points that are averaged: all but the first quarter (at least the first
    one), which may still be travelling from the biased start, and none reached by a clipped step
    (``travelling``, one flag per point); full Newton steps arrive within a step or two, after
    which the points scatter independently around the unbiased solution. When every step was
    clipped, the last point alone."""
    points = np.asarray(points, np.float64)
    if len(points) <= 1:
        return points
    start = max(1, len(points) // 4)
    if travelling is not None and any(travelling):
        start = max(start, max(i for i, t in enumerate(travelling) if t) + 1)
    return points[start:] if start < len(points) else points[-1:]


def gauss_newton_refinement(evaluate: Callable[[np.ndarray, int], tuple],
                            state: OptimizerState, steps: int, max_step: float = 1.0,
                            on_iteration: Callback | None = None) -> OptimizerState:
    """Gauss-Newton steps on decorrelated renders; returns the mean of the stepped-to points
    that have arrived (:func:`averaged_refinement_points`).

    Each step solves ``H dz = -g`` with ``g = (J1 + J2)^T r / 2`` and ``H`` the cross curvature
    of two independent Jacobians (:func:`cross_curvature`): with ``r``, ``J1`` and ``J2`` from
    three independent renders both are unbiased, so the step is the full Newton step on the
    expected objective rather than one shortened by the Jacobian noise (which, with ``J1^T J1``,
    took a third of the way per step at 16 spp on an IOR).

    Steps are clipped to a trust radius (largest change of any unconstrained coordinate, in
    typical steps) that starts at ``max_step``: a noisy Jacobian must not throw the fit far from
    the Levenberg-Marquardt solution. The radius doubles when a clipped step is followed by one
    pointing the same way (the solution is further than the radius, not noise: Levenberg-Marquardt's
    fixed-seed objective can sit many typical steps from it when the renders' Monte-Carlo
    variance changes with the parameters, as for a BRDF's specular lobe) and halves, down to
    ``max_step``, when a step turns back.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(z, iteration) -> (r, (J1, J2), loss)`` with independent fresh seeds for ``r``,
        ``J1`` and ``J2`` at every call.
    steps : int
        Number of steps (each costs one evaluation).
    max_step : float
        Initial and smallest trust radius (typical steps).
    """
    points = [np.asarray(p, np.float64) for p in state.moments.get("refinement", [])]
    travelling = list(state.moments.get("refinement_clipped", [False] * len(points)))
    radius = float(state.moments.get("refinement_radius", max_step))
    previous = state.moments.get("refinement_step")
    z = points[-1] if points else np.array(state.z, np.float64)
    while len(points) < steps:
        state.iteration += 1
        r, (J1, J2), loss = evaluate(z, state.iteration)
        state.history.append({"iteration": state.iteration, "loss": float(loss),
                              "z": list(map(float, z)), "phase": "refinement"})
        step = np.linalg.solve(cross_curvature(J1, J2), -0.5 * (J1 + J2).T @ r)
        if previous is not None:
            previous = np.asarray(previous, np.float64)
            agree = float(step @ previous) / max(float(np.linalg.norm(step) * np.linalg.norm(previous)), 1e-300)
            if travelling and travelling[-1] and agree > 0.5:
                radius *= 2.0
            elif agree < 0.0:
                radius = max(max_step, radius / 2.0)
        size = float(np.abs(step).max())
        clipped = size > radius
        step = step * min(1.0, radius / max(size, 1e-300))
        z = z + step
        points.append(z)
        travelling.append(clipped)
        previous = step
        state.moments.update(refinement=[p.tolist() for p in points], refinement_clipped=travelling,
                             refinement_radius=radius, refinement_step=step.tolist())
        state.z = np.mean(averaged_refinement_points(points, travelling), axis=0)
        if on_iteration is not None:
            on_iteration(state)
    return state


def adam(gradient: Callable[[np.ndarray, int], tuple[float, np.ndarray]], state: OptimizerState,
         max_iterations: int, learning_rate: float = 0.05, betas=(0.9, 0.999), eps: float = 1e-8,
         on_iteration: Callback | None = None) -> OptimizerState:
    """Adam (Kingma & Ba 2015) on ``gradient(z, iteration) -> (rmse, dL/dz)``.

    Returns the state whose ``z`` is the mean of the iterates of the last quarter of the run.
    """
    m = np.asarray(state.moments.get("m", np.zeros_like(state.z)), np.float64)
    v = np.asarray(state.moments.get("v", np.zeros_like(state.z)), np.float64)
    tail = np.asarray(state.moments.get("tail_sum", np.zeros_like(state.z)), np.float64)
    tail_count = int(state.moments.get("tail_count", 0))
    tail_start = max_iterations - max(1, max_iterations // 4)
    z = np.array(state.z, np.float64)
    while state.iteration < max_iterations:
        loss, g = gradient(z, state.iteration)
        t = state.iteration + 1
        m = betas[0] * m + (1 - betas[0]) * g
        v = betas[1] * v + (1 - betas[1]) * g * g
        step = learning_rate * (m / (1 - betas[0] ** t)) / (np.sqrt(v / (1 - betas[1] ** t)) + eps)
        state.history.append({"iteration": t, "loss": float(loss), "z": list(map(float, z))})
        z = z - step
        state.iteration = t
        if t > tail_start:
            tail += z
            tail_count += 1
        state.z = z
        state.moments = {"m": m.tolist(), "v": v.tolist(), "tail_sum": tail.tolist(),
                         "tail_count": tail_count}
        if on_iteration is not None:
            on_iteration(state)
    if tail_count:
        state.z = tail / tail_count
    return state
