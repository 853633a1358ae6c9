"""Fit extended models fully and decide whether an effect earns its place.

A candidate is accepted over a reference model only if both hold:

- **holdout**: the holdout views' RMSE falls by more than its noise. The noise has two parts: the
  pixel noise of the paired per-pixel difference of squared errors (both renderings use the same
  random numbers, so their own Monte-Carlo noise largely cancels), three standard errors of its
  mean; and the scatter of a refit, measured as how far the holdout RMSE moved when the
  reference model alone was fitted again with the same settings (the *control* fit).
- **BIC** on the training views prefers it: ``M ln(RSS_ext / RSS_ref) + k ln M < 0``, ``k`` the
  added scalars and ``M`` the compared residuals.

Effects that change how the renderer samples light (a rough interface, a spread exit point)
break the pairing of the holdout test; their comparisons use crossed errors of independent renders
(:func:`compare`), and their amounts are held at the short fit's value (:func:`fit_model`).

The control fit doubles as the reference: the extended model and the control start from the same
values and run the same optimiser with the same settings (:func:`model_settings` of the extended
model), so a better-converged fit of the old parameters cannot pass for a discovery.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from abs.diagnosis.effects import Candidate, effect
from abs.diagnosis.model import extend_scene, render_problem
from abs.errors import InputError
from abs.fitting import FitResult, FitSettings, OptimizerState, fit
from abs.model import render_views
from abs.runs.files import load_checkpoint, save_checkpoint
from abs.runs.identity import model_identity

__all__ = ["ModelFit", "Comparison", "fit_model", "model_settings", "compare", "HOLDOUT_Z"]

#: Standard errors by which the paired holdout improvement must exceed zero.
HOLDOUT_Z = 3.0
#: Crossed holdout errors (:func:`compare`) render at this many times the evaluation's samples
#: per pixel: their noise falls as 1 / spp^2 where rendering noise dominates.
CROSSED_SPP_FACTOR = 4


@dataclass
class ModelFit:
    """A model (the scene plus effects) fitted to the capture."""

    candidates: tuple[Candidate, ...]
    scene: object
    result: FitResult
    held: dict[str, np.ndarray] = field(default_factory=dict)
    #: The settings it was fitted with (:func:`model_settings`).
    settings: FitSettings | None = None

    @property
    def values(self) -> dict[str, np.ndarray]:
        """Every parameter of the model: fitted, and held at a short fit's amount."""
        return {**self.held, **self.result.values}

    @property
    def n_scalars(self) -> int:
        """Scalars estimated from the capture (held amounts included: a scan or an earlier
        round estimated them)."""
        return self.result.vector.size + sum(np.size(v) for v in self.held.values())

    @property
    def label(self) -> str:
        return " + ".join(c.label for c in self.candidates) or "baseline"

    def rmse(self, split: str) -> float:
        return float(self.result.metrics[f"{split}_rmse"]["after"])

    def n_train(self) -> int:
        return 3 * sum(int(v.mask.sum()) for v in self.result.views if not v.holdout)


def model_settings(settings: FitSettings, candidates: tuple[Candidate, ...],
                   settled: tuple[Candidate, ...] = ()) -> FitSettings:
    """The settings a model with ``candidates`` is fitted with: ``settings`` adjusted for what
    its effects need (full resolution, more samples per pixel, no refinement steps; see
    :class:`~abs.diagnosis.effects.Effect`), except those ``settled`` (held at accepted values,
    ``Effect.held_once_accepted``: their needs were those of fitting them)."""
    candidates = tuple(c for c in candidates if c not in settled)
    if any(effect(c.effect).full_resolution for c in candidates):
        settings = replace(settings, downsample=1)
    spp_factor = max((effect(c.effect).fit_spp_factor for c in candidates), default=1)
    if spp_factor > 1:
        settings = replace(settings, spp=settings.spp * spp_factor)
    if not all(effect(c.effect).fit_refinement for c in candidates):
        settings = replace(settings, refinement_steps=0)
    return settings


def fit_model(scene, capture, candidates: tuple[Candidate, ...], start: dict, settings: FitSettings,
              path: Path, resume: bool = False, settings_of: tuple[Candidate, ...] | None = None,
              settled: tuple[Candidate, ...] = ()) -> ModelFit:
    """Fit ``scene`` extended by ``candidates`` (its ``[fit]`` parameters and theirs) from
    ``start`` values; the extended scene file is written to ``path``.

    The fit runs with :func:`model_settings` of ``settings_of`` (default: ``candidates``) less
    ``settled``: accepted effects held at their ``start`` values
    (``Effect.held_once_accepted``), whose needs were those of fitting them. A
    control compared with a model that has one more effect passes that model's candidates, so
    both fit their shared parameters alike: an effect fitted at 8x the samples also converges
    the baseline's parameters better, and a control left at the plain samples would credit that
    to the effect (measured: a pose-only control at 8 spp stayed in a wrong minimum, 0.0586
    holdout, that the same control at 64 spp left, 0.0483, as the trial with a cloth lobe did,
    0.0486).

    The fit's optimiser state is checkpointed after every iteration next to ``path``
    (``<stem>.checkpoint/checkpoint.json``). With ``resume``, a checkpoint of the same fit (same
    extended scene, capture, parameters, start and settings) is continued: a finished fit then
    costs only its final renderings, an interrupted one goes on where it stopped; a checkpoint of
    another fit is ignored and overwritten.

    The parameters of effects with a vanishing derivative at null (rough glass, subsurface
    spread) are held at their ``start`` values, the amount the short fit's scan of crossed errors
    found (:mod:`abs.diagnosis.score`), and the rest is fitted around them. A gradient fit of
    them is not reliable at a diagnosis's samples: their derivatives are very noisy (measured on
    a roughness of 0.15: Gauss-Newton steps scattered by +-0.3 at 8 spp), and least squares on
    one noisy render also rewards whatever renders with less noise (rough glass lets light
    sampling reach through the interface), which pulled 0.15 to 0.35-0.45 with a worse holdout.
    """
    held_names = {p for c in candidates if effect(c.effect).zero_null_derivative or c in settled
                  for p in c.parameters}
    held = {n: np.asarray(start[n], float) for n in held_names}
    extended = extend_scene(scene, candidates, held, path)
    names = tuple(n for n in extended.fit_parameters if n not in held)
    settings = model_settings(settings, candidates if settings_of is None else settings_of,
                              settled)
    initial = {n: np.asarray(v, float) for n, v in start.items() if n in names}
    folder = path.with_name(path.stem + ".checkpoint")
    identity = model_identity(extended, capture, names, initial, settings)
    state = _saved_state(folder, identity) if resume else None
    result = fit(extended, capture, names, settings, initial=initial, resume=state,
                 on_iteration=lambda s: save_checkpoint(folder, identity, s.to_dict()))
    return ModelFit(tuple(candidates), extended, result, held, settings)


def _saved_state(folder: Path, identity: dict) -> OptimizerState | None:
    try:
        saved = load_checkpoint(folder, identity)
    except InputError:  # another fit's checkpoint (the diagnosis went another way): start afresh
        return None
    return None if saved is None else OptimizerState.from_dict(saved)


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
    #: What the holdout RMSEs measure: ``holdout RMSE`` (renders sharing seeds) or ``noise-free
    #: (crossed) holdout RMSE`` (effects that change the sampling, see :func:`compare`).
    holdout_measure: str = "holdout RMSE"

    def to_json(self) -> dict:
        return {"holdout_rmse_before": self.holdout_rmse_before,
                "holdout_rmse_after": self.holdout_rmse_after, "holdout_z": round(self.holdout_z, 3),
                "refit_scatter": self.refit_scatter, "delta_bic": round(self.delta_bic, 3),
                "added_scalars": self.added_scalars, "accepted": self.accepted, "reason": self.reason,
                "holdout_measure": self.holdout_measure}


def _holdout_renders(model: ModelFit, capture, spp: int, seed: int) -> dict[str, np.ndarray]:
    """The holdout views rendered at the model's fitted values, as a fit renders them for its
    metrics (unclamped)."""
    _, _, theta, problem = render_problem(model.scene, capture, tuple(model.result.values), True, 1,
                                          None, model.result.values)
    return render_views(problem, problem.observations, theta, spp, seed)


def _holdout_errors(reference: ModelFit, extended: ModelFit, crossed: tuple | None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel squared errors ``(e0, e1)`` of the two models on the holdout views.

    Without ``crossed``: of the fits' own ``after`` renders (shared seeds). With ``crossed =
    (capture, spp, seed)``: the crossed error ``(a - p) . (b - p)`` of two fresh renders per
    model from independent seeds, an unbiased estimate of the noise-free squared error."""
    e0, e1 = [], []
    if crossed is None:
        after = {v.name: v.after for v in extended.result.views}
        for v in reference.result.views:
            if v.holdout:
                e0.append(np.sum(np.square(v.after - v.photograph), axis=-1)[v.mask])
                e1.append(np.sum(np.square(after[v.name] - v.photograph), axis=-1)[v.mask])
    else:
        capture, spp, seed = crossed
        renders = {key: (_holdout_renders(m, capture, spp, seed),
                         _holdout_renders(m, capture, spp, seed + 1))
                   for key, m in (("ref", reference), ("ext", extended))}
        for v in reference.result.views:
            if v.holdout:
                for key, out in (("ref", e0), ("ext", e1)):
                    a, b = renders[key][0][v.name], renders[key][1][v.name]
                    out.append(np.sum((a - v.photograph) * (b - v.photograph), axis=-1)[v.mask])
    return np.concatenate(e0), np.concatenate(e1)


def _changes_sampling(reference: ModelFit, extended: ModelFit) -> bool:
    """``extended`` adds an effect that changes how the renderer samples light paths (a rough
    interface, a spread exit point), so equal seeds no longer give the two models the same paths,
    or one that reweights each path by its own amount (``Effect.crossed_comparison``: the
    threads' lobes), so the same paths no longer carry the same noise."""
    return any(effect(c.effect).zero_null_derivative or effect(c.effect).crossed_comparison
               for c in set(extended.candidates) ^ set(reference.candidates))


def compare(reference: ModelFit, extended: ModelFit, refit_scatter: float, capture,
            settings: FitSettings) -> Comparison:
    """Decide whether ``extended`` (more effects) beats ``reference``.

    The paired holdout test relies on common random numbers: both models' renders share seeds,
    so their Monte-Carlo noise largely cancels in the per-pixel difference. An effect that
    changes the sampling itself (:func:`_changes_sampling`) breaks that pairing, and a plain
    squared error would then reward whichever model renders with less noise (measured: rough
    glass at 0.11 for a true 0.15 raised the plain holdout RMSE from 0.0527 to 0.0538, z = -1.5,
    while its noise-free holdout error fell from 0.0233 to 0.0192, z = 5.7). Such comparisons
    use crossed errors of two independent renders per model, which estimate the noise-free
    misfit.

    Parameters
    ----------
    refit_scatter : float
        How much the holdout RMSE moves between two fits of one model (radiance units).
    capture : Capture
    settings : FitSettings
        The fits' settings (``eval_spp`` and ``seed`` of the second holdout renders).
    """
    # Refits that land on the same point differ only by float32 round-off (summation order across
    # threads): below 1e-7 radiance the scatter is that, and reporting it would make the JSON
    # depend on thread scheduling.
    refit_scatter = round(float(refit_scatter), 7)
    crossed = None
    if _changes_sampling(reference, extended):
        spp = CROSSED_SPP_FACTOR * (settings.eval_spp or extended.scene.render.spp)
        crossed = (capture, spp, settings.seed + 7919)
    e0, e1 = _holdout_errors(reference, extended, crossed)
    d = e0 - e1
    mean, se = float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))
    # The RMSEs reported are those of the errors compared (per channel, as the fits report them).
    h0, h1 = (float(np.sqrt(max(e.mean(), 0.0) / 3)) for e in (e0, e1))
    z = mean / se if se > 0 else (np.inf if mean > 0 else 0.0)
    m = extended.n_train()
    k = extended.n_scalars - reference.n_scalars
    rss0, rss1 = m * reference.rmse("train") ** 2, m * extended.rmse("train") ** 2
    delta_bic = m * float(np.log(rss1 / rss0)) + k * float(np.log(m))
    # With crossed errors the plain RMSEs carry the noise the comparison removes: the margin is
    # the paired test's alone.
    holdout_ok = z > HOLDOUT_Z and (crossed is not None or h0 - h1 > refit_scatter)
    measure = "holdout RMSE" if crossed is None else "noise-free (crossed) holdout RMSE"
    bic_ok = delta_bic < 0
    if holdout_ok and bic_ok:
        reason = (f"{measure} {h0:.4g} -> {h1:.4g} ({HOLDOUT_Z:g} sigma margin passed: "
                  f"z = {z:.1f}, refit scatter {refit_scatter:.2g}) and BIC prefers it "
                  f"(delta {delta_bic:.1f})")
    else:
        failed = []
        if not holdout_ok:
            margin = "" if crossed is not None else f" and a drop > refit scatter {refit_scatter:.2g}"
            failed.append(f"{measure} {h0:.4g} -> {h1:.4g} is not an improvement beyond noise "
                          f"(z = {z:.1f}, needs > {HOLDOUT_Z:g}{margin})")
        if not bic_ok:
            failed.append(f"BIC does not prefer it (delta {delta_bic:+.1f})")
        reason = "; ".join(failed)
    return Comparison(h0, h1, float(z), float(refit_scatter), float(delta_bic), int(k),
                      bool(holdout_ok and bic_ok), reason, measure)
