"""``adam``: Adam on stochastic gradients, the optimiser for many scalars.

Adam (Kingma & Ba 2015) takes a new render seed per iteration (unbiased, independent gradients)
and follows the settings' spp and resolution schedules (coarse to fine). Reverse-mode gradients
cost about two renders per view whatever the number of scalars, where Levenberg-Marquardt's
Jacobian costs one per scalar: the choice for textures and BRDF coefficients. The result is the
average of the last quarter of the iterates, which cancels most of the Monte-Carlo jitter of the
final steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from abs.fitting.optimisers import Callback, Optimiser, OptimizerState, register

__all__ = ["Adam", "AdamState", "adam"]


@dataclass(frozen=True, eq=False)
class AdamState:
    """Adam's memory (all over the unconstrained vector ``z``, shape (P,)).

    Attributes
    ----------
    m, v : ndarray
        First and second moment estimates of the gradient.
    tail_sum : ndarray
        Sum of the iterates of the last quarter of the run (their mean is the answer).
    tail_count : int
        Iterates in ``tail_sum``.
    """

    m: np.ndarray
    v: np.ndarray
    tail_sum: np.ndarray
    tail_count: int = 0

    @classmethod
    def zeros(cls, size: int) -> "AdamState":
        return cls(np.zeros(size), np.zeros(size), np.zeros(size), 0)

    def to_dict(self) -> dict:
        # Keys as checkpoints have always had them (the state was a dictionary once).
        return {"m": self.m.tolist(), "v": self.v.tolist(), "tail_sum": self.tail_sum.tolist(),
                "tail_count": self.tail_count}

    @classmethod
    def from_dict(cls, d: dict) -> "AdamState":
        return cls(np.asarray(d["m"], np.float64), np.asarray(d["v"], np.float64),
                   np.asarray(d["tail_sum"], np.float64), int(d.get("tail_count", 0)))


@register("adam")
class Adam(Optimiser):
    """Adam over ``max_iterations`` steps of ``learning_rate`` typical steps (the settings')."""

    State = AdamState

    def run(self, objective, state: OptimizerState, settings,
            on_iteration: Callback | None = None) -> OptimizerState:
        return adam(objective.gradient, state, settings.max_iterations, settings.learning_rate,
                    on_iteration=on_iteration)


def adam(gradient: Callable[[np.ndarray, int], tuple[float, np.ndarray]], state: OptimizerState,
         max_iterations: int, learning_rate: float = 0.05, betas=(0.9, 0.999), eps: float = 1e-8,
         on_iteration: Callback | None = None) -> OptimizerState:
    """Adam (Kingma & Ba 2015) on ``gradient(z, iteration) -> (rmse, dL/dz)``.

    Returns the state whose ``z`` is the mean of the iterates of the last quarter of the run.
    """
    saved = state.solver or AdamState.zeros(state.z.size)
    m, v, tail, tail_count = saved.m, saved.v, saved.tail_sum, saved.tail_count
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
            tail = tail + z
            tail_count += 1
        state.z = z
        state.solver = AdamState(m, v, tail, tail_count)
        if on_iteration is not None:
            on_iteration(state)
    if tail_count:
        state.z = tail / tail_count
    return state
