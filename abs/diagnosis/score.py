"""Rank candidate effects cheaply, before fitting any of them.

Score (Lagrange-multiplier) test: at the current model's fitted values ``theta_0`` and the
candidate's null value, the renderer gives the residuals ``r`` and their Jacobian ``J = [N, C]``
(``N``: the already fitted parameters, ``C``: the candidate's). The drop in the sum of squared
residuals that one Gauss-Newton step over all of them would buy, beyond what the fitted
parameters alone buy, in units of the pixel noise, is

    S = (r^T P_J r - r^T P_N r) / sigma^2,     P_X = X (X^T X)^-1 X^T,

with ``sigma^2`` the residual variance left after the full step. Under the null (the effect is
absent) ``S`` is chi-square with ``k`` degrees of freedom (``k``: the candidate's scalars), so
``S - k ln M`` (``M`` residuals) predicts the candidate's gain in BIC; that is what ranks them.
Subtracting the ``N`` part removes what a not quite converged fit of the old parameters would
explain. The Jacobian comes from a render independent of the residual's (no noise correlation).

Effects whose derivative vanishes at the null value (``Effect.zero_null_derivative``, e.g. a
roughness of 0) are invisible to this test; they get a short fit of their own parameters alone,
and ``S`` is the drop in squared residuals it achieves (a likelihood-ratio statistic, same scale).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from abs.diagnosis.effects import Candidate, effect
from abs.fitting.fit import prepare
from abs.fitting.observations import observe
from abs.fitting.parameters import ParameterVector
from abs.fitting.problem import FitProblem
from abs.fitting.settings import FitSettings

__all__ = ["CandidateScore", "score_candidates"]

SHORT_FIT_ITERATIONS = 4
#: The score test renders with this many times the fits' samples per pixel: its power grows with
#: the samples (S scales as 1 / sigma^2) and it costs one Jacobian, so it can afford them.
SCORE_SPP_FACTOR = 4


@dataclass(frozen=True)
class CandidateScore:
    """How strongly the residuals ask for one candidate.

    Attributes
    ----------
    candidate : Candidate
    statistic : float
        ``S`` (chi-square units; see the module docstring).
    dof : int
        The candidate's number of scalars ``k``.
    n_residuals : int
        ``M``, the compared residuals (training pixels x 3).
    method : str
        ``"score test"`` or ``"short fit"`` (zero derivative at the null value).
    start : dict
        Values to start a full fit from: one Gauss-Newton step (score test), or the short fit's
        result, kept inside the bounds.
    """

    candidate: Candidate
    statistic: float
    dof: int
    n_residuals: int
    method: str
    start: dict = field(default_factory=dict, repr=False)

    @property
    def predicted_bic_gain(self) -> float:
        """``S - k ln M``: positive when BIC is expected to prefer the extended model."""
        return self.statistic - self.dof * float(np.log(self.n_residuals))

    def to_json(self) -> dict:
        return {"effect": self.candidate.effect, "score": round(self.statistic, 3),
                "target": self.candidate.target, "parameters": list(self.candidate.parameters),
                "dof": self.dof, "predicted_bic_gain": round(self.predicted_bic_gain, 3),
                "method": self.method}


def _projected(X: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``P_X r``: the part of ``r`` in the column space of ``X`` (columns scaled for rank)."""
    if X.shape[1] == 0:
        return np.zeros_like(r)
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(X / scale, r, rcond=1e-10)
    return (X / scale) @ coef


def _inside(vector: ParameterVector, theta: np.ndarray, candidate: slice) -> np.ndarray:
    """``theta`` clipped to the bounds; a candidate's bounded scalars (absorption >= 0) start 5 %
    of its largest estimate inside, where the optimiser's transform still has a usable slope."""
    lo, hi = vector.lower, vector.upper
    theta = np.clip(theta, lo, hi)
    offset = np.abs(theta[candidate] - np.where(np.isfinite(lo[candidate]), lo[candidate], 0.0))
    margin = 0.05 * max(float(np.max(offset)), 1e-3)
    theta[candidate] = np.clip(theta[candidate], lo[candidate] + margin, hi[candidate] - margin)
    return theta


def score_candidates(scene, capture, base_parameters, candidates: list[Candidate],
                     settings: FitSettings, full_resolution: bool = False) -> list[CandidateScore]:
    """Score candidates against the current model, sharing one Jacobian among them.

    Parameters
    ----------
    scene : Scene
        The current model (its fitted values) with every candidate added at its null value (see
        :func:`abs.diagnosis.model.extend_scene`); at the null values it renders exactly like the
        current model, so one render and one Jacobian column per scalar serve every candidate.
    capture : Capture
    base_parameters : sequence of str
        The parameters already fitted (the nuisance ``N``).
    candidates : list of Candidate
    settings : FitSettings
        ``spp``, ``downsample``, ``clamp`` and ``seed`` of the renders.
    full_resolution : bool
        The current model holds an effect that needs full resolution (an accepted pose): every
        candidate is then scored without downsampling.
    """
    scores = {}
    groups: dict[int, list[Candidate]] = {}
    for c in candidates:
        e = effect(c.effect)
        if e.zero_null_derivative:
            scores[c] = _short_fit(scene, capture, c, settings)
        else:
            factor = 1 if e.full_resolution or full_resolution else settings.downsample
            groups.setdefault(factor, []).append(c)
    for factor, group in groups.items():
        names = tuple(base_parameters) + tuple(p for c in group for p in c.parameters)
        _, compiled, capture, names = prepare(scene, capture, names)
        vector = ParameterVector.build(compiled.specs, names, {n: compiled.get(n) for n in names})
        theta0 = np.concatenate([compiled.get(n) for n in names])  # exactly the null, not clipped
        problem = FitProblem(compiled, vector, [observe(v, factor) for v in capture.train_views],
                             settings.clamp)
        r, J = problem.residuals(theta0, SCORE_SPP_FACTOR * settings.spp, settings.seed + 501,
                                 jacobian=True,
                                 jacobian_seed=settings.seed + 502)
        slices = vector.slices()
        base = np.concatenate([np.arange(slices[n].start, slices[n].stop) for n in base_parameters]
                              or [np.zeros(0, int)])
        nuisance = _projected(J[:, base], r)
        for c in group:
            own = np.concatenate([np.arange(slices[p].start, slices[p].stop) for p in c.parameters])
            cols = np.concatenate([base, own])
            Jc = J[:, cols]
            full = _projected(Jc, r)
            m, p = Jc.shape
            sigma2 = float(np.sum((r - full) ** 2)) / max(m - p, 1)
            statistic = (float(full @ full) - float(nuisance @ nuisance)) / max(sigma2, 1e-300)
            scale = np.linalg.norm(Jc, axis=0)
            scale[scale == 0] = 1.0
            step, *_ = np.linalg.lstsq(Jc / scale, -r, rcond=1e-10)
            sub = ParameterVector.build(compiled.specs, tuple(base_parameters) + c.parameters,
                                        {n: compiled.get(n) for n in names})
            start = _inside(sub, theta0[cols] + step / scale, slice(base.size, cols.size))
            scores[c] = CandidateScore(c, max(statistic, 0.0), own.size, m, "score test",
                                       sub.split(start))
    return [scores[c] for c in candidates]


def _short_fit(scene, capture, candidate, settings) -> CandidateScore:
    from abs.fitting.fit import fit

    short = replace(settings, max_iterations=SHORT_FIT_ITERATIONS, refinement_steps=1)
    result = fit(scene, capture, candidate.parameters, short)
    before, after = result.metrics["train_rmse"]["before"], result.metrics["train_rmse"]["after"]
    m = 3 * sum(int(v.mask.sum()) for v in result.views if not v.holdout)
    # Likelihood ratio with the variance left after the fit: M ln(RSS_before / RSS_after).
    statistic = m * float(np.log(before ** 2 / max(after ** 2, 1e-300)))
    dof = int(result.vector.size)
    start = {n: v for n, v in result.values.items()}
    return CandidateScore(candidate, max(float(statistic), 0.0), dof, m, "short fit", start)
