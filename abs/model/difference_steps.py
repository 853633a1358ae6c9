"""The step of a parameter's central differences, chosen from a pilot of its Jacobian column.

A parameter that moves what is seen through glass (an IOR) takes its derivative by central
differences with common random numbers (:meth:`abs.render.compiled.CompiledScene.render_forward`):
with the same samples at ``p +- h``, a sample whose path crosses an edge seen through the glass
contributes its jump divided by ``2 h``. Those jumps are rare and large, so the column's render
noise grows as ``h`` shrinks (measured on the glass suite: about ``h^-1.4``), while its signal
is the image's derivative averaged over ``[p - h, p + h]``, which keeps its size only while the
image is near linear over that range. Which ``h`` is best depends on the scene:

- glass spheres before the checkerboard (``glass.ior`` at 120x100 over 2, 64 spp, 12 seeds):
  from 0.02 to 0.04 the signal energy halves (10 900 to 5 600; 6 700 to 2 600): the
  checkerboard's edges move by pixels over that range; the parameter's noise per render
  (``noise / signal^2``) grows 1.5 to 2.7x;
- a thin-walled bowl framed before it: the signal stays (534, 486, 388 at 0.02, 0.04, 0.08)
  while the noise falls 2.3-2.7x per doubling; ``noise / signal^2`` falls 3.3x from 0.02 to 0.08.

:func:`choose_difference_steps` renders the column at the parameter's own step and at 2x and 4x
it, from :data:`PILOT_SEEDS` independent seeds, and keeps the step with the least noise per
signal among those that keep at least :data:`SIGNAL_KEPT` of the largest signal: a smaller
signal is the derivative averaged over a range where the image is far from linear (its
curvature would understate what the photographs measure, and inflate the standard errors).
Where the pilot renders matters: at IOR 1.5 the spheres' signal kept two thirds at 0.08, and
a sphere of IOR 1.62 fitted with that step ended at 1.6115 +- 0.0036 (1.6185 +- 0.0014 with
0.02). A fit runs it at its own start, after the starts (:func:`abs.fitting.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DifferenceStep", "choose_difference_steps", "MULTIPLES", "PILOT_SEEDS", "SIGNAL_KEPT"]

#: Steps tried, as multiples of the parameter's own ``difference_step``.
MULTIPLES = (1, 2, 4)
#: Independent renders of the column per step tried.
PILOT_SEEDS = 8
#: A step must keep this share of the largest signal energy among those tried.
SIGNAL_KEPT = 0.5
#: Seeds of the pilot renders, clear of those a fit uses.
_PILOT_SEED = 50_000_000


@dataclass(frozen=True)
class DifferenceStep:
    """One parameter's pilot and the step it chose.

    Attributes
    ----------
    name : str
        The parameter (``glass.ior``).
    step : float
        The chosen step (the parameter's units).
    tried : list of dict
        Per step tried: ``step``, ``signal`` (the column's squared norm without its noise: the
        mean product of independent renders' columns, summed over the compared pixels, in
        (image units / parameter unit)^2) and ``noise`` (the summed per-pixel variance of one
        render's column, same units).
    """

    name: str
    step: float
    tried: list

    def to_dict(self) -> dict:
        """``fit.json``'s entry for this parameter under ``difference_steps``."""
        return {"step": self.step, "tried": self.tried}


def column_signal_and_noise(columns: np.ndarray) -> tuple[float, float]:
    """Signal energy ``|E J|^2`` (unbiased: the mean product of distinct renders' columns) and
    noise ``sum Var J`` of ``columns`` (K independent renders, K >= 2, each (M,))."""
    columns = np.asarray(columns, np.float64)
    k = len(columns)
    total = columns.sum(axis=0)
    signal = (float(total @ total) - float(np.sum(columns * columns))) / (k * (k - 1))
    noise = float(np.sum(columns.var(axis=0, ddof=1)))
    return signal, noise


def _pick(tried: list) -> float:
    """The step with the least ``noise / signal^2`` among those that keep :data:`SIGNAL_KEPT`
    of the largest signal; the first (the parameter's own) when no signal is resolved."""
    best = max(t["signal"] for t in tried)
    if best <= 0.0:
        return tried[0]["step"]
    kept = [t for t in tried if t["signal"] >= SIGNAL_KEPT * best]
    return min(kept, key=lambda t: t["noise"] / t["signal"] ** 2)["step"]


def choose_difference_steps(problem, theta: np.ndarray, spp: int, seed: int = 0) -> dict[str, DifferenceStep]:
    """Choose the central-difference step of every varying parameter that has one.

    Parameters
    ----------
    problem : FitProblem
        The comparison the fit makes (its views, resolution and samples where glass is seen).
    theta : ndarray
        Physical values where the pilot renders (the fit's start).
    spp : int
        Samples per pixel of the pilot renders (the fit's).
    seed : int
        The fit's seed.

    Returns
    -------
    dict of str to DifferenceStep
        Per parameter with a ``difference_step``; the compiled scene is left with the chosen
        steps set (:meth:`~abs.render.compiled.CompiledScene.set_difference_step`).
    """
    compiled, vector = problem.compiled, problem.vector
    chosen = {}
    for name, where in vector.slices().items():
        own = compiled.specs[name].difference_step
        if own is None:
            continue
        tried = []
        for multiple in MULTIPLES:
            compiled.set_difference_step(name, own * multiple)
            # All of the parameter's columns as one vector (one per channel of a separable IOR).
            columns = [problem.jacobian(theta, spp, seed + _PILOT_SEED + k, names=[name])[:, where].ravel()
                       for k in range(PILOT_SEEDS)]
            signal, noise = column_signal_and_noise(columns)
            tried.append({"step": own * multiple, "signal": signal, "noise": noise})
        step = _pick(tried)
        compiled.set_difference_step(name, step)
        chosen[name] = DifferenceStep(name, step, tried)
    return chosen
