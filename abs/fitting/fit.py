"""``abs.fit``: fit named scene parameters to a capture, with uncertainty.

One call does the whole job: render every view with the initial parameters, optimise on the
training views, render every view again, and estimate standard errors and correlations by the
Laplace approximation. The optimisation is an objective (``objective.py``: the weighted
residuals of the forward model, ``abs.model``) handed to an optimiser looked up by name
(``optimisers/``: Levenberg-Marquardt or Adam). Holdout views are
never fitted; they are rendered and reported before and after. Storage (fit.json, checkpoints,
report) and progress display are the caller's: pass ``on_iteration`` to observe the run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from abs.fitting.checks import run_checks
from abs.fitting.laplace import (LaplaceApproximation, laplace, monte_carlo_spread, with_extra_covariance,
                                 with_monte_carlo_error)
from abs.fitting.objective import Objective
from abs.fitting.optimisers import OptimizerState, get
from abs.fitting.optimisers.lm import pair_seeds
from abs.fitting.polish import LinePolish, polish, polished_monte_carlo_covariance
from abs.fitting.scan import channel_curves, default_grid, parabola_minimum
from abs.fitting.settings import FitSettings, explicit_steps
from abs.fitting.starts import StartChoice, choose_start
from abs.metrics import ssim
from abs.model import ParameterVector, build_model, estimate_image_noise, render_views
from abs.model.difference_steps import DifferenceStep, choose_difference_steps
from abs.render.contacts import coincident_surfaces

__all__ = ["fit", "FitResult", "ViewRenderings", "MONTE_CARLO_MIN_POINTS"]

#: Fewest refinement targets (or recording pairs) whose scatter counts as measuring the
#: estimate's Monte-Carlo error, so that the Laplace part leaves the renders' noise out.
MONTE_CARLO_MIN_POINTS = 4


@dataclass(frozen=True)
class ViewRenderings:
    """A view's photograph and its renderings before and after the fit (full resolution)."""

    name: str
    holdout: bool
    photograph: np.ndarray
    before: np.ndarray
    after: np.ndarray
    mask: np.ndarray


@dataclass
class FitResult:
    """What a fit found. :meth:`summary` is the content of ``fit.json``."""

    vector: ParameterVector
    values: dict[str, np.ndarray]
    initial: dict[str, np.ndarray]
    uncertainty: LaplaceApproximation
    metrics: dict[str, dict[str, float]]
    method: str
    iterations: int
    renders: int
    samples_rendered: int
    wall_s: float
    history: list[dict]
    views: list[ViewRenderings] = field(repr=False, default_factory=list)
    truth: dict[str, list] | None = None
    image_noise: float | None = None
    checks: list[str] = field(default_factory=list)
    scan: dict | None = None
    limited: dict[str, np.ndarray] | None = None
    starts: StartChoice | None = None
    monte_carlo_points: int = 0
    difference_steps: dict[str, DifferenceStep] | None = None
    data_correlation: np.ndarray | None = None  # (P, P), of the photographs' (Laplace) share alone
    polishes: list[LinePolish] = field(default_factory=list)
    pixel_weights: bool = False  # residuals weighed by the capture's noise images

    def summary(self) -> dict:
        """``fit.json`` (public contract, see docs/fitting.md, "Outputs")."""
        stderr = self.vector.split(self.uncertainty.stderr)
        parameters = {}
        for name, unit in zip(self.vector.names, self.vector.units):
            entry = {"value": self.values[name].tolist(),
                     "stderr": [None if not np.isfinite(s) else float(s) for s in stderr[name]],
                     "unit": unit, "initial": self.initial[name].tolist()}
            if self.truth and name in self.truth:
                entry["truth"] = list(self.truth[name])
            if self.limited is not None:
                # Share of the refinement's steps (after its first quarter) cut to the trust
                # radius, per component: near 1, the renders' noise moved it (checks.py).
                entry["refinement_limited"] = [round(float(x), 4) for x in self.limited[name]]
            parameters[name] = entry

        def table(corr: np.ndarray) -> dict:
            return {"names": self.vector.labels(),
                    "matrix": [[None if not np.isfinite(c) else round(float(c), 6) for c in row]
                               for row in corr]}

        return {
            "parameters": parameters,
            "correlation": table(self.uncertainty.correlation),
            # The photographs' share alone (the Laplace part): what they can and cannot tell
            # apart, without the renders' Monte-Carlo error, which moves scalars together.
            **({"data_correlation": table(self.data_correlation)}
               if self.data_correlation is not None else {}),
            "pixel_sigma": self.uncertainty.pixel_sigma,
            **self.metrics,
            "renders": self.renders,
            "samples_rendered": self.samples_rendered,
            "wall_s": round(self.wall_s, 3),
            "iterations": self.iterations,
            "method": self.method,
            # Iterates whose scatter gave the standard errors' Monte-Carlo part (0 or 1: none).
            "monte_carlo_points": self.monte_carlo_points,
            "image_noise": self.image_noise,
            "pixel_weights": self.pixel_weights,
            "checks": list(self.checks),
            **({"scan": self.scan} if self.scan else {}),
            **({"starts": self.starts.to_dict()} if self.starts is not None else {}),
            **({"difference_steps": {n: d.to_dict() for n, d in self.difference_steps.items()}}
               if self.difference_steps else {}),
            **({"polish": [p.to_dict() for p in self.polishes]} if self.polishes else {}),
        }


def _refinement_curvatures(found, objective: Objective) -> list[np.ndarray]:
    """An optimiser's cross curvatures of the weighted residuals in ``z``
    (:meth:`~abs.fitting.optimisers.Optimiser.curvatures`) in :func:`laplace`'s units: ``J^T J``
    of the pixel residuals in physical units, without the priors' rows (which :func:`laplace`
    adds itself). The objective's Jacobian is ``J dtheta/dz / sigma`` with the priors'
    ``dtheta/dz / sd`` below, so each is ``sigma^2 (H / (d d^T) - diag(1 / sd^2))`` with ``d``
    the transform's derivative where it was rendered."""
    if found is None:
        return []
    precision = np.where(objective.has_prior, 1.0 / np.square(objective.prior_sd), 0.0)
    out = []
    for H, z in zip(*found):
        d = objective.vector.derivative(z)
        if np.all(np.abs(d) > 1e-150):  # a coordinate deep at a bound: its scale is lost
            out.append(objective.sigma ** 2 * (H / np.outer(d, d) - np.diag(precision)))
    return out


def _metrics(observations, renders) -> dict[str, float]:
    out = {}
    for split, holdout in (("train", False), ("holdout", True)):
        chosen = [o for o in observations if o.holdout == holdout]
        if not chosen:
            out[f"{split}_rmse"] = out[f"{split}_ssim"] = None
            continue
        sq = sum(float(np.sum(np.square(renders[o.name] - o.photograph)[o.mask])) for o in chosen)
        out[f"{split}_rmse"] = float(np.sqrt(sq / sum(3 * o.pixels for o in chosen)))
        out[f"{split}_ssim"] = float(np.mean([ssim(renders[o.name], o.photograph, o.mask)
                                              for o in chosen]))
    return out


def _free_scan(objective: Objective, theta: np.ndarray) -> dict | None:
    """The seeds' per-channel scan of a fitted glass absorption around the fit, in ``scan.json``'s
    format, when the absorption reweights from path-length recordings: every point reweights the
    recordings of Levenberg-Marquardt's first seed (at the fitted IOR and pose, when those were
    fitted too: a scan of the absorption given them)."""
    vector, compiled = objective.vector, objective.model.compiled
    slices = vector.slices()
    reweightable = objective.problem().reweightable
    for name in vector.names:
        spec = compiled.specs[name]
        if spec.reweighting != "absorption" or name in vector.tied or name not in reweightable:
            continue
        s = slices[name]
        grids = [default_grid(spec, v, 15) if v > spec.lower else np.linspace(0.0, 1.0, 15)
                 for v in theta[s]]
        curves = channel_curves(objective.problem(), theta, grids, objective.settings.spp,
                                objective.settings.seed, offset=s.start)
        return {"parameter": name, "unit": spec.unit,
                "minimum": [parabola_minimum(g, c) for g, c in zip(grids, curves)],
                "channels": [{"values": g.tolist(), "rmse": c.tolist()} for g, c in zip(grids, curves)]}
    return None


def fit(scene, capture, parameters=None, settings: FitSettings = FitSettings(),
        initial: dict[str, object] | None = None, resume: OptimizerState | None = None,
        on_iteration: Callable[[OptimizerState], None] | None = None,
        truth: dict[str, list] | None = None) -> FitResult:
    """Fit scene parameters to a capture's training views.

    Parameters
    ----------
    scene : Scene or path
        The scene file; its current values are the starting point.
    capture : Capture or path
        Capture folder (``cameras.json``); holdout views are only evaluated.
    parameters : sequence of str, optional
        Parameter names (``glass.absorption``, ``environment.scale``, ``sphere.pose``...);
        default: the scene's ``[fit] parameters``.
    settings : FitSettings
        With ``starts``, short fits from several values choose the start first
        (:mod:`abs.fitting.starts`; recorded in the summary's ``starts``).
    initial : dict, optional
        Starting values by parameter name, instead of the scene file's (several starts begin
        from these too, but for the parameters they set).
    resume : OptimizerState, optional
        Continue an interrupted fit (from its checkpoint).
    on_iteration : callable, optional
        Called with the :class:`OptimizerState` after every iteration (progress, checkpoints).
    truth : dict, optional
        Known true values (synthetic captures), copied into the summary for comparison.

    Returns
    -------
    FitResult
    """
    t0 = time.perf_counter()
    starts = None
    if resume is not None and resume.start is not None:
        starts = StartChoice.from_dict(resume.start)
    elif settings.starts and resume is None:
        starts = choose_start(scene, capture, parameters, settings, initial)
    if starts is not None:
        initial = {**(initial or {}), **starts.values}
    model = build_model(scene, capture, parameters, initial, settings.tie, settings.reweight,
                        settings.glass_spp_factor, explicit_steps(settings))
    scene, compiled, vector, names, counter = (model.scene, model.compiled, model.vector,
                                               model.names, model.counter)
    steps = None
    if settings.difference_steps == "auto":
        # At the full fit's start (after the starts, whose short fits take the parameters' own
        # steps): what a step keeps of the signal depends on where it is measured (a sphere's
        # image is far less linear in its IOR near 1.62 than at 1.5).
        steps = choose_difference_steps(model.problem("train", settings.downsample, settings.clamp),
                                        vector.initial, settings.spp, settings.seed)
    priors = {n: p for n, p in scene.fit_priors.items() if n in names}
    method = settings.resolved_method(vector.size)
    optimiser = get(method)
    if resume is not None and (resume.method != method or resume.z.size != vector.size):
        raise ValueError(f"checkpoint is a {resume.method} fit of {resume.z.size} scalars; this "
                         f"fit is {method} with {vector.size}")
    full = model.problem("all", 1, settings.clamp)
    eval_spp = settings.eval_spp or scene.render.spp
    before = render_views(full, full.observations, vector.initial, eval_spp, settings.seed + 1)

    # Pixel noise (photograph + Monte-Carlo) weighs the pixels against the priors.
    first = model.problem("train", settings.downsample, settings.clamp)
    obs = first.observations[0]
    sigma = float(np.hypot(
        estimate_image_noise(obs.photograph, obs.camera),
        estimate_image_noise(first.render(obs, vector.initial, settings.spp, settings.seed + 3),
                             obs.camera)))
    sigma = max(sigma, 1e-4)
    objective = Objective.build(model, settings, sigma, priors)
    has_prior, prior_sd = objective.has_prior, objective.prior_sd

    state = resume or OptimizerState(method, 0, vector.to_unconstrained(vector.initial),
                                     start=None if starts is None else starts.to_dict())
    previous_wall = float(state.history[-1].get("wall_s", 0.0)) if state.history else 0.0

    def iteration_done(s: OptimizerState) -> None:
        s.history[-1]["wall_s"] = previous_wall + time.perf_counter() - t0
        if on_iteration is not None:
            on_iteration(s)

    state = optimiser.run(objective, state, settings, iteration_done)

    theta = vector.to_physical(state.z)
    # Uncertainty at the optimum, from renders independent of each other (the Jacobian's own
    # noise): fresh ones, or, from recordings, those of the refinement's seed pairs (the optimum
    # minimises the mean over all pairs, so it depends on any one pair's noise by a share only).
    problem = objective.problem()
    seeds = (settings.seed + 99, settings.seed + 98, settings.seed + 97)
    if objective.reweighted and settings.refinement_steps >= 1 and method == "lm":
        seeds = (*pair_seeds(settings.seed, 1), pair_seeds(settings.seed, 0)[0])
    r, J = problem.residuals(theta, settings.spp, seeds[0], jacobian=True, jacobian_seed=seeds[1])
    prior = np.where(has_prior, prior_sd, np.inf) if has_prior.any() else None
    J2 = problem.jacobian(theta, settings.spp, seeds[2])
    points, scatter = optimiser.averaged_points(state), optimiser.scatter_points(state)
    # When the estimate's Monte-Carlo error is measured (below), the pixel noise of the Laplace
    # part is the photographs' and the model's alone: from two independent renders' residuals.
    measured = points is not None and len(monte_carlo_spread(points, scatter)) >= MONTE_CARLO_MIN_POINTS
    r2 = problem.residuals(theta, settings.spp, settings.seed + 96)[0] if measured else None
    # The refinement's own Jacobian pairs near the optimum average into the curvature: an IOR's
    # column through glass is noisy, and one pair's cross curvature can leave it unresolved.
    nearby = _refinement_curvatures(optimiser.curvatures(state), objective)
    correlation = problem.noise_correlation()
    uncertainty = laplace(r, J, prior, jacobian2=J2, curvatures=nearby, residuals2=r2,
                          correlation=correlation)
    # A curvature still unresolved may be resolved by more pairs at the optimum: up to three
    # more before saying so.
    more = []
    while not uncertainty.identifiable.all() and len(more) < 3:
        seed = settings.seed + 90 - 2 * len(more)
        more.append((problem.jacobian(theta, settings.spp, seed), problem.jacobian(theta, settings.spp, seed - 1)))
        uncertainty = laplace(r, J, prior, jacobian2=J2, more_pairs=more, curvatures=nearby,
                              residuals2=r2, correlation=correlation)
    monte_carlo_points = 0
    photographs = uncertainty  # the photographs' part alone, before the renders' error is added
    if points is not None:
        physical = lambda zs: None if zs is None else np.array([vector.to_physical(p) for p in zs])  # noqa: E731
        uncertainty = with_monte_carlo_error(uncertainty, physical(points), physical(scatter),
                                             sequential=optimiser.sequential_points(state))
        monte_carlo_points = len(monte_carlo_spread(points, scatter))
    polishes = []
    if settings.polish_spp is not None:
        # Central differences' secant slopes have their own fixed point; a last parabola
        # along the objective itself puts those scalars at its minimum (polish.py), the others
        # moved with them as the photographs' covariance correlates them. The Laplace part
        # stays the one at the optimiser's estimate, a fraction of a difference step away.
        z, polishes = polish(objective, state.z, settings.polish_spp, settings.polish_pairs,
                             settings.seed, {n: d.step for n, d in (steps or {}).items()},
                             photographs.covariance, photographs.identifiable)
        theta = vector.to_physical(z)
        # A polished scalar's Monte-Carlo error is the polish's, not the optimiser's.
        extra = polished_monte_carlo_covariance(uncertainty.covariance - photographs.covariance,
                                                vector, polishes)
        uncertainty = with_extra_covariance(photographs, extra)
    scans = _free_scan(objective, theta)
    after = render_views(full, full.observations, theta, eval_spp, settings.seed + 1)

    limited = optimiser.limited_steps(state)
    limited = None if limited is None or not len(limited) else vector.split(np.mean(limited, axis=0))

    m_before, m_after = _metrics(full.observations, before), _metrics(full.observations, after)
    metrics = {key: {"before": m_before[key], "after": m_after[key]} for key in m_before}
    # The noise a perfect model would leave: the photographs' and the renderings' own, on the
    # views the checks judge (holdout views when there are any). The renderings' is measured from
    # a second rendering of those views: Monte-Carlo noise through glass is heavy-tailed, and an
    # estimate from one image reads its typical size, not its RMS (on a built capture, 113 for a
    # measured 636).
    judged = [o for o in full.observations if o.holdout] or full.observations
    again = render_views(full, judged, theta, eval_spp, settings.seed + 10007)
    image_noise = float(np.mean([np.hypot(
        estimate_image_noise(o.photograph, o.camera),
        float(np.sqrt(np.mean(np.square(after[o.name] - again[o.name])[o.mask]) / 2.0)))
        for o in judged]))
    views = [ViewRenderings(o.name, o.holdout, o.photograph, before[o.name], after[o.name], o.mask)
             for o in full.observations]
    history = [{**h, "values": {k: v.tolist() for k, v in vector.split(vector.to_physical(h["z"])).items()}}
               for h in state.history]
    # The starts' short fits count in renders and time (a resumed fit counts only what it
    # rendered itself, as for the optimiser's renders).
    renders, samples = counter.renders, counter.samples
    if starts is not None and resume is None:
        renders, samples = renders + starts.renders, samples + starts.samples_rendered
    result = FitResult(vector, vector.split(theta), vector.split(vector.initial), uncertainty,
                       metrics, method, state.iteration, renders, samples,
                       previous_wall + time.perf_counter() - t0, history, views, truth, image_noise,
                       scan=scans, limited=limited, starts=starts,
                       monte_carlo_points=monte_carlo_points, difference_steps=steps,
                       data_correlation=photographs.correlation,
                       pixel_weights=problem.weights is not None, polishes=polishes)
    kinds = {n: (scene.materials[compiled.specs[n].owner].type_name, compiled.specs[n].field)
             for n in names if compiled.specs[n].owner in scene.materials}
    # The scene's own geometry first: coincident surfaces make the renders themselves ambiguous.
    result.checks = [c.message() for c in coincident_surfaces(compiled)] + run_checks(
        result.summary(), {n: (compiled.specs[n].lower, compiled.specs[n].upper) for n in names},
        kinds, vector.split(vector.step))
    return result
