"""Fit extended models fully and decide whether an effect earns its place.

Squared errors are measured *crossed*: each fitted model renders every view twice with
independent random numbers, ``a`` and ``b``, and a pixel's error is ``(a - p) . (b - p)`` (``p``
the photograph). Its expectation is the squared error of the noise-free rendering (plus the
photograph's noise), whereas ``|a - p|^2`` adds the rendering's own Monte-Carlo variance, so a
model that merely renders with less noise (rough glass lets light sampling reach through it)
would look better fitted. Both models use the same two seeds (paired comparisons).

A candidate is accepted over a reference model only if all hold:

- **holdout**: the holdout views' crossed error falls by more than its noise: three standard
  errors of the mean per-pixel drop, and more than the scatter of a refit, measured as how far
  the holdout error moved when the reference model alone was fitted again with the same
  settings (the *control* fit); and the holdout RMSE of the fit's own evaluation falls too.
- **BIC** on the training views prefers it: ``M ln(RSS_ext / RSS_ref) + k ln M < 0``, ``k`` the
  added scalars, ``M`` the compared residuals and ``RSS`` the crossed sums.

The control fit doubles as the reference: the extended model and the control start from the same
values and run the same optimiser, so a better-converged fit of the old parameters cannot pass
for a discovery.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from abs.diagnosis.effects import Candidate, effect
from abs.diagnosis.model import extend_scene
from abs.fitting import FitResult, FitSettings, fit
from abs.fitting.fit import prepare
from abs.fitting.observations import observe
from abs.fitting.parameters import ParameterVector
from abs.fitting.problem import FitProblem

__all__ = ["ModelFit", "Comparison", "fit_model", "compare", "HOLDOUT_Z"]

#: Standard errors by which the paired holdout improvement must exceed zero.
HOLDOUT_Z = 3.0
#: Seeds of the two independent evaluation renders of every model (shared by all models).
CROSSED_SEEDS = (7001, 7002)


@dataclass
class ModelFit:
    """A model (the scene plus effects) fitted to the capture."""

    candidates: tuple[Candidate, ...]
    scene: object
    result: FitResult
    crossed: dict[str, np.ndarray]   # view name -> per-pixel crossed squared error (see module)

    @property
    def values(self) -> dict[str, np.ndarray]:
        return self.result.values

    @property
    def label(self) -> str:
        return " + ".join(c.label for c in self.candidates) or "baseline"

    def rmse(self, split: str) -> float:
        return float(self.result.metrics[f"{split}_rmse"]["after"])

    def n_train(self) -> int:
        return 3 * sum(int(v.mask.sum()) for v in self.result.views if not v.holdout)

    def crossed_errors(self, split: str) -> np.ndarray:
        """Per-pixel crossed squared errors (RGB summed) of the ``split`` views, concatenated."""
        return np.concatenate([self.crossed[v.name] for v in self.result.views
                               if v.holdout == (split == "holdout")])

    def crossed_rmse(self, split: str) -> float:
        """RMSE of the noise-free rendering, estimated from the crossed errors (radiance)."""
        return float(np.sqrt(max(self.crossed_errors(split).mean(), 0.0) / 3.0))


def crossed_errors(scene, capture, values: dict, settings: FitSettings) -> dict[str, np.ndarray]:
    """``(a - p) . (b - p)`` per pixel of every view (RGB summed; masked pixels only), ``a`` and
    ``b`` renders of ``scene`` at ``values`` with the :data:`CROSSED_SEEDS`, at full resolution
    and the fits' evaluation samples per pixel."""
    names = tuple(values)
    _, compiled, capture, names = prepare(scene, capture, names)
    vector = ParameterVector.build(compiled.specs, names, {n: compiled.get(n) for n in names})
    theta = np.concatenate([np.asarray(values[n], float).ravel() for n in names])
    problem = FitProblem(compiled, vector, [observe(v, 1) for v in capture.views], settings.clamp)
    spp = settings.eval_spp or compiled.scene.render.spp
    out = {}
    for i, o in enumerate(problem.observations):
        a, b = (problem.render(o, theta, spp, seed + 7 * i) for seed in CROSSED_SEEDS)
        out[o.name] = np.sum((a - o.photograph) * (b - o.photograph), axis=-1)[o.mask]
    return out


def fit_model(scene, capture, candidates: tuple[Candidate, ...], start: dict, settings: FitSettings,
              path: Path) -> ModelFit:
    """Fit ``scene`` extended by ``candidates`` (its ``[fit]`` parameters and theirs) from
    ``start`` values; the extended scene file is written to ``path``."""
    extended = extend_scene(scene, candidates, {}, path)
    names = extended.fit_parameters
    if any(effect(c.effect).full_resolution for c in candidates):
        settings = replace(settings, downsample=1)
    initial = {n: np.asarray(v, float) for n, v in start.items() if n in names}
    result = fit(extended, capture, names, settings, initial=initial)
    return ModelFit(tuple(candidates), extended, result,
                    crossed_errors(extended, capture, result.values, settings))


@dataclass(frozen=True)
class Comparison:
    """The evidence for (or against) an extended model over a reference model."""

    holdout_rmse_before: float
    holdout_rmse_after: float
    holdout_z: float
    refit_scatter: float
    delta_bic: float
    added_scalars: int
    accepted: bool
    reason: str

    def to_json(self) -> dict:
        return {"holdout_rmse_before": self.holdout_rmse_before,
                "holdout_rmse_after": self.holdout_rmse_after, "holdout_z": round(self.holdout_z, 3),
                "refit_scatter": self.refit_scatter, "delta_bic": round(self.delta_bic, 3),
                "added_scalars": self.added_scalars, "accepted": self.accepted, "reason": self.reason}


def _paired_holdout(reference: ModelFit, extended: ModelFit) -> tuple[float, float]:
    """Mean and standard error of the per-pixel drop in crossed squared error on the holdout views."""
    d = reference.crossed_errors("holdout") - extended.crossed_errors("holdout")
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))


def compare(reference: ModelFit, extended: ModelFit, refit_scatter: float) -> Comparison:
    """Decide whether ``extended`` (more effects) beats ``reference``.

    Parameters
    ----------
    refit_scatter : float
        How much the holdout crossed RMSE moves between two fits of one model (radiance units).
    """
    h0, h1 = reference.rmse("holdout"), extended.rmse("holdout")
    c0, c1 = reference.crossed_rmse("holdout"), extended.crossed_rmse("holdout")
    mean, se = _paired_holdout(reference, extended)
    z = mean / se if se > 0 else (np.inf if mean > 0 else 0.0)
    m = extended.n_train()
    k = extended.result.vector.size - reference.result.vector.size
    rss0 = max(float(np.sum(reference.crossed_errors("train"))), 1e-300)
    rss1 = max(float(np.sum(extended.crossed_errors("train"))), 1e-300)
    delta_bic = m * float(np.log(rss1 / rss0)) + k * float(np.log(m))
    holdout_ok = z > HOLDOUT_Z and c0 - c1 > refit_scatter and h1 < h0
    bic_ok = delta_bic < 0
    if holdout_ok and bic_ok:
        reason = (f"holdout RMSE {h0:.4g} -> {h1:.4g} (noise-free estimate {c0:.4g} -> {c1:.4g}; "
                  f"{HOLDOUT_Z:g} sigma margin passed: z = {z:.1f}, refit scatter "
                  f"{refit_scatter:.2g}) and BIC prefers it (delta {delta_bic:.1f})")
    else:
        failed = []
        if not holdout_ok:
            failed.append(f"holdout RMSE {h0:.4g} -> {h1:.4g} (noise-free estimate {c0:.4g} -> "
                          f"{c1:.4g}) is not an improvement beyond noise (z = {z:.1f}, needs > "
                          f"{HOLDOUT_Z:g}, a drop > refit scatter {refit_scatter:.2g} and a lower "
                          f"holdout RMSE)")
        if not bic_ok:
            failed.append(f"BIC does not prefer it (delta {delta_bic:+.1f})")
        reason = "; ".join(failed)
    return Comparison(h0, h1, float(z), float(refit_scatter), float(delta_bic), int(k),
                      bool(holdout_ok and bic_ok), reason)
