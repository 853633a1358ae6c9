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
roughness of 0) are invisible to this test; they get a short fit instead: a scan of their amount
around a small, plausible value (``Effect.probe``, times 1/4 to 4). Per pixel the crossed error ``(a - p) . (b -
p)`` of two independent renders estimates the noise-free misfit (a rendering's own variance would
otherwise favour whatever renders with less noise); ``S = z^2`` of the paired z test of its drop
from the null to the best amount (chi-square scale, like the score statistic).
"""

from __future__ import annotations

from collections.abc import MutableMapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from abs.diagnosis.effects import Candidate, effect
from abs.diagnosis.model import render_problem
from abs.fitting.settings import FitSettings
from abs.model import ParameterVector
from abs.runs.identity import digest, model_identity

__all__ = ["CandidateScore", "score_candidates"]

#: The short fit's renders use this many times the fits' samples per pixel: a crossed error's
#: noise falls as 1 / spp^2 where rendering noise dominates, and a scan is a handful of renders.
SHORT_FIT_SPP_FACTOR = 16
#: Amounts (times the effect's probe value) at which an effect invisible to the score test is tried.
PROBE_SCALES = (0.25, 0.5, 1.0, 2.0, 4.0)


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


def _priors(scene, vector: ParameterVector) -> tuple[np.ndarray, np.ndarray]:
    """Prior means and standard deviations of ``vector``'s scalars from the scene's
    ``[fit.priors]`` (sd ``inf`` where a scalar has none)."""
    mean, sd = np.zeros(vector.size), np.full(vector.size, np.inf)
    for name, where in vector.slices().items():
        prior = scene.fit_priors.get(name)
        if prior is not None and prior.mean.size == where.stop - where.start:
            mean[where], sd[where] = prior.mean, prior.sd
    return mean, sd


def _step(J: np.ndarray, r: np.ndarray, sigma2: float, theta: np.ndarray, prior_mean: np.ndarray,
          prior_sd: np.ndarray) -> np.ndarray:
    """One Gauss-Newton step from ``theta`` for residuals ``r`` with Jacobian ``J``, with the
    scalars' Gaussian priors as extra rows weighed against the pixel noise ``sigma2``.

    Without priors it is the plain least-squares step. A direction the photographs do not
    constrain (a colour matrix's overall gain against a fitted brightness: ``k M`` and the scale
    over ``k`` render alike) is singular but for Monte-Carlo noise, and its step would be
    arbitrarily large (measured: a colour matrix's diagonal started at 5474); the effect's prior
    (:mod:`abs.diagnosis.effects.colour_transform`) pins it, as it does in the fit.
    """
    has = np.isfinite(prior_sd)
    if not has.any():
        scale = np.linalg.norm(J, axis=0)
        scale[scale == 0] = 1.0
        step, *_ = np.linalg.lstsq(J / scale, -r, rcond=1e-10)
        return step / scale
    sigma = np.sqrt(max(sigma2, 1e-300))
    rows = np.zeros((int(has.sum()), J.shape[1]))
    rows[np.arange(rows.shape[0]), np.flatnonzero(has)] = 1.0 / prior_sd[has]
    A = np.vstack([J / sigma, rows])
    b = np.concatenate([-r / sigma, -(theta[has] - prior_mean[has]) / prior_sd[has]])
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    step, *_ = np.linalg.lstsq(A / scale, b, rcond=1e-10)
    return step / scale


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
                     settings: FitSettings, full_resolution: bool = False,
                     saved: MutableMapping[str, dict] | None = None) -> list[CandidateScore]:
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
    saved : mutable mapping, optional
        Scores by a key of everything they depend on (scene file, capture, candidates, settings):
        found ones are reused, new ones added. The diagnosis passes a file-backed mapping, so a
        resumed run does not repeat them. A score test is saved too, though it is one Jacobian:
        recomputed, its step (a trial's start) differs in the last bits (gradients accumulate
        atomically, in an order that depends on thread scheduling), so the trial's checkpoint
        would no longer match and a finished fit would run again.
    """
    scores = {}
    groups: dict[int, list[Candidate]] = {}
    for c in candidates:
        e = effect(c.effect)
        if e.zero_null_derivative:
            used = (replace(settings, downsample=1) if e.full_resolution or full_resolution
                    else settings)
            key = _saved_key(scene, capture, "short fit", c.parameters, [c], used, saved)
            if key is not None and key in saved:
                scores[c] = _restored(c, saved[key])
                continue
            scores[c] = _short_fit(scene, capture, c, used)
            if key is not None:
                saved[key] = _record(scores[c])
        else:
            factor = 1 if e.full_resolution or full_resolution else settings.downsample
            groups.setdefault(factor, []).append(c)
    for factor, group in groups.items():
        names = tuple(base_parameters) + tuple(p for c in group for p in c.parameters)
        key = _saved_key(scene, capture, "score test", names, group,
                         replace(settings, downsample=factor), saved)
        if key is not None and key in saved:
            scores.update({c: _restored(c, saved[key][i]) for i, c in enumerate(group)})
            continue
        compiled, vector, theta0, problem = render_problem(scene, capture, names, False, factor, settings.clamp)
        # The test's power grows with the samples (S scales as 1 / sigma^2, mostly render
        # noise) and it costs one Jacobian, so it affords more than a fit's iteration.
        spp = max(effect(c.effect).score_spp_factor for c in group) * settings.spp
        r, J = problem.residuals(theta0, spp, settings.seed + 501,
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
            sub = ParameterVector.build(compiled.specs, tuple(base_parameters) + c.parameters,
                                        {n: compiled.get(n) for n in names})
            step = _step(Jc, r, sigma2, theta0[cols], *_priors(scene, sub))
            start = _inside(sub, theta0[cols] + step, slice(base.size, cols.size))
            scores[c] = CandidateScore(c, max(statistic, 0.0), own.size, m, "score test",
                                       sub.split(start))
        if key is not None:
            saved[key] = [_record(scores[c]) for c in group]
    return [scores[c] for c in candidates]


def _saved_key(scene, capture, method: str, names, group: list[Candidate], settings: FitSettings,
               saved: MutableMapping | None) -> str | None:
    """A digest of what the scores of ``group`` by ``method`` depend on, ``names`` the parameters
    that enter them (``None``: nothing is saved, or the scene has no file)."""
    source = getattr(scene, "source", None)
    if saved is None or source is None or not Path(source).is_file():
        return None
    what = {**model_identity(scene, capture, list(names), {}, settings), "method": method,
            "candidates": [[c.effect, c.target] for c in group]}
    return digest(what, 24)


def _record(score: CandidateScore) -> dict:
    return {"statistic": float(score.statistic), "dof": score.dof,
            "n_residuals": score.n_residuals, "method": score.method,
            "start": {n: np.asarray(v, float).ravel().tolist() for n, v in score.start.items()}}


def _restored(candidate: Candidate, entry: dict) -> CandidateScore:
    return CandidateScore(candidate, float(entry["statistic"]), int(entry["dof"]),
                          int(entry["n_residuals"]), entry["method"],
                          {n: np.asarray(v, float) for n, v in entry["start"].items()})


def _scan(tried, null_error: float) -> list:
    """``tried(scale)`` at increasing ``PROBE_SCALES`` until the mean crossed error has risen at
    two consecutive amounts (counting from the null's ``null_error``).

    The error is convex in the amount near the null (quadratic where the image responds linearly),
    so once it rises, larger amounts fit worse still and cannot hold the best drop; waiting for a
    second rise keeps one pair of renders' noise from ending the scan. An effect the photographs
    do not show rises at once: its scan costs two amounts instead of five (the box scene's three
    subsurface targets took 223 s of a 555-s scoring round at 160x120 with all five).
    """
    grid, previous, rises = [], null_error, 0
    for scale in PROBE_SCALES:
        grid.append(tried(scale))
        rises = rises + 1 if grid[-1][1] > previous else 0
        previous = grid[-1][1]
        if rises == 2:
            break
    return grid


def _short_fit(scene, capture, candidate, settings) -> CandidateScore:
    """Scan the candidate's amount along its probe direction (``PROBE_SCALES`` times
    :meth:`Effect.probe`) and compare the crossed training errors at the best amount and at the
    null, all from the same two seeds (paired: their Monte-Carlo noise largely cancels).

    A scan rather than a gradient fit: at the null the slope vanishes, and these effects'
    gradients (a spread exit point, a rough interface) are noisy at the few samples a diagnosis
    can afford, so a short gradient fit wanders; a handful of paired renders does not. The best
    amount (refined between grid points by a parabola) is the effect's estimate: the full fit
    holds it (:func:`abs.diagnosis.select.fit_model`). The scan stops early once larger amounts
    only fit worse (:func:`_scan`).
    """
    names = candidate.parameters
    _, vector, null, problem = render_problem(scene, capture, names, False, settings.downsample,
                                              settings.clamp)
    probe = effect(candidate.effect).probe(candidate.target)
    probe = np.concatenate([np.asarray(probe[n], float).ravel() for n in names])
    spp = SHORT_FIT_SPP_FACTOR * settings.spp

    def crossed(theta) -> np.ndarray:
        # Per pixel, (a - p) . (b - p) from two independent renders: the squared error of the
        # noise-free rendering. |a - p|^2 would add the rendering's own variance, which these
        # effects change (rough glass lets light sampling reach through it).
        ra, _ = problem.residuals(theta, spp, settings.seed + 503)
        rb, _ = problem.residuals(theta, spp, settings.seed + 504)
        return (ra * rb).reshape(-1, 3).sum(axis=1)

    e0 = crossed(null)

    def tried(scale: float) -> tuple[float, float, np.ndarray]:
        """(z of the drop, mean crossed error, theta) at ``scale`` times the probe."""
        theta = np.clip(null + scale * (probe - null), vector.lower, vector.upper)
        e = crossed(theta)
        drop = e0 - e
        return (float(drop.mean() / max(drop.std(ddof=1) / np.sqrt(drop.size), 1e-300)),
                float(e.mean()), theta)

    grid = _scan(tried, float(e0.mean()))
    j = int(np.argmax([g[0] for g in grid]))
    if 0 < j < len(grid) - 1:
        # The amount between grid points: the vertex of a parabola through the best point and its
        # neighbours in log amount (the grid is geometric).
        x = np.log(PROBE_SCALES[j - 1:j + 2])
        a, b, _ = np.polyfit(x, [g[1] for g in grid[j - 1:j + 2]], 2)
        if a > 0:
            grid.append(tried(float(np.exp(np.clip(-b / (2 * a), x[0], x[2])))))
    z, _, best_theta = max(grid, key=lambda g: g[0])
    z = max(z, 0.0)
    m = problem.n_residuals
    # A paired z test of the drop in crossed error over pixels; z^2 is on the chi-square scale of
    # the score statistics (one scalar).
    return CandidateScore(candidate, z * z, int(vector.size), m, "short fit",
                          vector.split(best_theta))
