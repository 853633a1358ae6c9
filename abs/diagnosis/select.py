"""Fit extended models fully and decide whether an effect earns its place.

A candidate is accepted over a reference model only if both hold:

- **holdout**: the holdout views' RMSE falls by more than its noise. The noise has two parts: the
  pixel noise of the paired per-pixel difference of squared errors (both renderings use the same
  random numbers, so their own Monte-Carlo noise largely cancels), three standard errors of its
  mean; and the scatter of a refit, measured as how far the holdout RMSE moved when the
  reference model alone was fitted again with the same settings (the *control* fit).
- **BIC** on the training views prefers it: ``M ln(RSS_ext / RSS_ref) + k ln M < 0``, ``k`` the
  added scalars and ``M`` the compared residuals.

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

__all__ = ["ModelFit", "Comparison", "fit_model", "compare", "HOLDOUT_Z"]

#: Standard errors by which the paired holdout improvement must exceed zero.
HOLDOUT_Z = 3.0


@dataclass
class ModelFit:
    """A model (the scene plus effects) fitted to the capture."""

    candidates: tuple[Candidate, ...]
    scene: object
    result: FitResult

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
    return ModelFit(tuple(candidates), extended, result)


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


def _paired_holdout(reference: FitResult, extended: FitResult) -> tuple[float, float]:
    """Mean and standard error of the per-pixel drop in squared error on the holdout views."""
    after = {v.name: v.after for v in extended.views}
    drops = []
    for v in reference.views:
        if v.holdout:
            e0 = np.sum(np.square(v.after - v.photograph), axis=-1)[v.mask]
            e1 = np.sum(np.square(after[v.name] - v.photograph), axis=-1)[v.mask]
            drops.append(e0 - e1)
    d = np.concatenate(drops)
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))


def compare(reference: ModelFit, extended: ModelFit, refit_scatter: float) -> Comparison:
    """Decide whether ``extended`` (more effects) beats ``reference``.

    Parameters
    ----------
    refit_scatter : float
        How much the holdout RMSE moves between two fits of one model (radiance units).
    """
    h0, h1 = reference.rmse("holdout"), extended.rmse("holdout")
    mean, se = _paired_holdout(reference.result, extended.result)
    z = mean / se if se > 0 else (np.inf if mean > 0 else 0.0)
    m = extended.n_train()
    k = extended.result.vector.size - reference.result.vector.size
    rss0, rss1 = m * reference.rmse("train") ** 2, m * extended.rmse("train") ** 2
    delta_bic = m * float(np.log(rss1 / rss0)) + k * float(np.log(m))
    holdout_ok = z > HOLDOUT_Z and h0 - h1 > refit_scatter
    bic_ok = delta_bic < 0
    if holdout_ok and bic_ok:
        reason = (f"holdout RMSE {h0:.4g} -> {h1:.4g} ({HOLDOUT_Z:g} sigma margin passed: "
                  f"z = {z:.1f}, refit scatter {refit_scatter:.2g}) and BIC prefers it "
                  f"(delta {delta_bic:.1f})")
    else:
        failed = []
        if not holdout_ok:
            failed.append(f"holdout RMSE {h0:.4g} -> {h1:.4g} is not an improvement beyond noise "
                          f"(z = {z:.1f}, needs > {HOLDOUT_Z:g} and a drop > refit scatter "
                          f"{refit_scatter:.2g})")
        if not bic_ok:
            failed.append(f"BIC does not prefer it (delta {delta_bic:+.1f})")
        reason = "; ".join(failed)
    return Comparison(h0, h1, float(z), float(refit_scatter), float(delta_bic), int(k),
                      bool(holdout_ok and bic_ok), reason)
