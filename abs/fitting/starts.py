"""Several starts: short fits from several values of a parameter choose where the full fit starts.

A glass's IOR seen through a sphere before a checkerboard has more than one basin: the
checkerboard matches itself at more than one magnification (the glass suite's sphere-1.47, fitted
from IOR 1.75 alone, ended at 1.646 +- 0.007, its truth 1.47, and no check could tell). A fit
from one start cannot know which basin it is in; short fits from starts across the physically
possible range end in their basins, and their ends can be compared.

Comparing the ends needs care: one seed pair's two-seed objective at the short fits' resolution
scatters more than the ends differ (sphere-1.47's four ends: 108, 62, 235, 395 from the short
fits' own pair). Its expectation is the noise-free squared error, so the mean over
:data:`SCORE_PAIRS` fresh pairs at :data:`SCORE_SPP_FACTOR` times the samples compares ends in
different basins without any render's noise favouring one (the same four ends: 1.63, 1.62, 2.74,
5.90, which tells the two in the truth's basin from the two in others). The ends are scored at
the full fit's own comparison (its ``downsample``), not the short fits' coarser one: a coarse
render has as many samples per pixel on fewer pixels, so its objective is noisier, while the
detail that tells the ends apart is averaged away. The glass suite's bowl framed before the
checkerboard (IOR 1.52): the end at IOR 1.417 without absorption against the truth differs by
0.44 in expectation at a quarter of the resolution with a standard error of 0.65 over four pairs
(it was chosen), by 2.8 +- 0.8 at half (every end scored with the same seeds, so the paired
differences are what count).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from abs.fitting.settings import explicit_steps
from abs.model import build_model

__all__ = ["StartChoice", "choose_start", "short_settings", "SCORE_PAIRS", "SCORE_SPP_FACTOR",
           "SHORT_ITERATIONS"]

#: Scoring the short fits' ends: this many fresh seed pairs at this many times their samples.
SCORE_PAIRS, SCORE_SPP_FACTOR = 4, 4
#: Levenberg-Marquardt evaluations of a short fit (enough to settle in a basin, not to finish).
SHORT_ITERATIONS = 6
#: Seeds of the scoring renders, above the fit's seed: clear of those the short fits use.
_SCORE_SEED = 1000


@dataclass(frozen=True)
class StartChoice:
    """The short fits and the start they chose.

    Attributes
    ----------
    values : dict of str to ndarray
        The chosen short fit's end, by parameter name (physical units): the full fit's start.
    tried : list of dict
        Per short fit: ``start`` (the values it started from), ``end`` (where it ended) and
        ``objective`` (the mean two-seed objective at its end; half the sum of squared pixel
        residuals, linear RGB, at the full fit's ``downsample``) and ``objective_se`` (its
        standard error over the scoring pairs).
    chosen : int
        Index into ``tried``.
    renders, samples_rendered : int
        What the short fits and their scoring rendered.
    """

    values: dict[str, np.ndarray]
    tried: list[dict]
    chosen: int
    renders: int = 0
    samples_rendered: int = 0

    def to_dict(self) -> dict:
        """JSON form (``fit.json``'s ``starts``, a checkpoint's ``start``)."""
        return {"values": {n: np.ravel(v).tolist() for n, v in self.values.items()},
                "tried": self.tried, "chosen": self.chosen, "renders": self.renders,
                "samples_rendered": self.samples_rendered}

    @classmethod
    def from_dict(cls, d: dict) -> "StartChoice":
        return cls({n: np.asarray(v, np.float64) for n, v in d["values"].items()},
                   list(d["tried"]), int(d["chosen"]), int(d.get("renders", 0)),
                   int(d.get("samples_rendered", 0)))


def short_settings(settings):
    """The short fits' settings: the full fit's coarsest comparison (its first coarse-to-fine
    stage, else its ``downsample``), :data:`SHORT_ITERATIONS` evaluations (at most the full
    fit's), no refinement, no further starts, no polish (a short fit only has to find a
    basin; polished, the glass suite's starts rendered 2.6 times the samples), and no pilot of
    difference steps (given steps are kept; ``"auto"`` becomes the parameters' own: the full fit
    chooses at its own start)."""
    coarse = max([settings.downsample] + [f for _, f in settings.downsample_schedule])
    steps = () if settings.difference_steps == "auto" else settings.difference_steps
    return replace(settings, downsample=coarse, downsample_schedule=(),
                   max_iterations=min(SHORT_ITERATIONS, settings.max_iterations),
                   refinement_steps=0, starts=(), difference_steps=steps, polish_spp=None)


def _start_points(starts) -> list[dict[str, list[float]]]:
    """Every combination of the start values: ``(("glass.ior", (1.45, 1.55)),)`` -> two points,
    each value for all channels of its parameter."""
    names = [name for name, _ in starts]
    return [dict(zip(names, combo)) for combo in itertools.product(*(values for _, values in starts))]


def choose_start(scene, capture, names, settings, initial=None, run_fit=None) -> StartChoice:
    """Short fits from every combination of ``settings.starts``; the end with the lowest mean
    two-seed objective (see the module docstring) is the full fit's start.

    Parameters
    ----------
    scene : Scene or path
    capture : Capture or path
    names : sequence of str
        The fitted parameters.
    settings : FitSettings
        The full fit's settings; ``starts`` lists ``(parameter, values)``, each value set for
        every channel of that parameter (other parameters start at ``initial`` or the scene's).
    initial : dict, optional
        Start values of the other parameters.
    run_fit : callable, optional
        ``run_fit(scene, capture, names, settings, initial=...) -> FitResult`` (default:
        :func:`abs.fitting.fit`).

    Returns
    -------
    StartChoice
    """
    if run_fit is None:
        from abs.fitting.fit import fit as run_fit
    short = short_settings(settings)
    spp = short.spp * SCORE_SPP_FACTOR
    # One model scores every end (a fresh compile per end would cost more than its renders).
    model = build_model(scene, capture, names, initial, settings.tie, settings.reweight,
                        settings.glass_spp_factor, explicit_steps(settings))
    problem, vector = model.problem("train", settings.downsample, settings.clamp), model.vector
    unknown = [n for n, _ in settings.starts if n not in vector.names]
    if unknown:
        raise ValueError(f"starts name {', '.join(unknown)}, which this fit does not fit "
                         f"({', '.join(vector.names)})")
    tried, ends, renders, samples = [], [], 0, 0
    for point in _start_points(settings.starts):
        start = {**(initial or {})}
        for name, value in point.items():
            start[name] = [float(value)] * model.compiled.specs[name].size
        result = run_fit(scene, capture, names, short, initial=start)
        renders, samples = renders + result.renders, samples + result.samples_rendered
        end = {n: np.asarray(v, np.float64) for n, v in result.values.items()}
        # The end in the vector's layout (a tied parameter's one value).
        theta = np.concatenate([end[n][:1] if n in vector.tied else end[n] for n in vector.names])
        pairs = [0.5 * float(problem.residuals(theta, spp, settings.seed + _SCORE_SEED + 2 * k)[0]
                             @ problem.residuals(theta, spp, settings.seed + _SCORE_SEED + 2 * k + 1)[0])
                 for k in range(SCORE_PAIRS)]
        tried.append({"start": {n: [float(v)] for n, v in point.items()},
                      "end": {n: v.tolist() for n, v in end.items()}, "objective": float(np.mean(pairs)),
                      "objective_se": float(np.std(pairs, ddof=1) / np.sqrt(len(pairs)))})
        ends.append(end)
    chosen = int(np.argmin([t["objective"] for t in tried]))
    return StartChoice(ends[chosen], tried, chosen, renders + model.counter.renders,
                       samples + model.counter.samples)
