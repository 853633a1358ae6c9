"""``abs.sample``: the posterior of scene parameters given a capture, by emcee around a fit.

Steps: (1) a point estimate and Laplace standard errors, from ``abs.fit`` or a given fit;
(2) the noise model at the fit: each photograph's white-noise variance (Immerkaer) and the
render's per-pixel Monte-Carlo variance from two independent renders at the sampling spp;
(3) the posterior of :class:`~abs.sampling.posterior.RenderPosterior` (same parameters, bounds
and priors as ``abs fit``; crossed likelihood of two fixed-seed renders, see
:mod:`abs.sampling.likelihood`); (4) walkers in a ball of ``ball`` Laplace standard errors around
the fit; (5) emcee until the autocorrelation time is resolved or a budget is spent, the chain in
an HDF5 file that a resumed run continues; (6) summaries and posterior predictive renderings.

The chain file also holds (group ``abs``) what the chain belongs to and its noise model, so a
resume uses the same likelihood and a resume of a different problem is refused.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import emcee
import h5py
import numpy as np

from abs.errors import InputError, read_json
from abs.render.contacts import coincident_surfaces
from abs.runs.files import check_identity
from abs.runs.identity import run_identity
from abs.sampling.calibration import calibrate_render_noise
from abs.sampling.checks import run_checks
from abs.sampling.ensemble import EnsembleProgress, run_ensemble
from abs.sampling.likelihood import NoiseModel, render_variance
from abs.sampling.mode import find_mode
from abs.sampling.posterior import LogPrior, RenderPosterior
from abs.sampling.predictive import PredictiveView, posterior_predictive
from abs.sampling.summary import burn_in, parameter_summary

__all__ = ["SampleSettings", "SampleResult", "sample", "read_start"]

_GROUP = "abs"


@dataclass(frozen=True)
class SampleSettings:
    """How ``abs.sample`` samples.

    Attributes
    ----------
    spp : int
        Samples per pixel of each of the two likelihood renders per view. Render noise
        widens the posterior (the chain's fixed seeds offset its mode; the likelihood allows for
        it, calibrated by ``calibration_pairs``), and through glass it is heavy-tailed at low
        spp: on the 16x12-pixel test scene a render costs 0.3 s at 64 spp and 0.9 s at 512.
    downsample : int
        Compare images box-averaged by this factor (fewer, less noisy pixels: faster, and the
        likelihood's Gaussian approximation of the render noise holds better).
    clamp : float or None
        Clamp renderings at this value (photographs that saturate).
    walkers : int
        Ensemble size (0: ``max(8, 4 P)`` rounded up to even, P the number of scalars).
    max_steps : int
        Chain length cap (steps of the whole ensemble, resumed runs included).
    max_renders : int or None
        Render budget of the chain (likelihood renders; each evaluation renders every training
        view twice; none from path-length recordings, where the budget does not bind).
    ball : float
        Walkers start at the fit plus ``ball`` Laplace standard errors times N(0, 1).
    check_every : int
        Steps between autocorrelation estimates.
    noise_renders : int
        Independent renders per view that estimate the render variance at the fit.
    calibration_pairs : int
        Further seed pairs rendered at the mode to recentre the likelihood on their average and
        calibrate its render variance (:mod:`abs.sampling.calibration`); 0: neither.
    predictive_draws : int
        Posterior draws rendered for the posterior predictive images.
    eval_spp : int or None
        Samples per pixel of the posterior predictive renders (default: the scene's).
    fit_iterations, fit_refinement_steps : int
        Settings of the fit that gives the starting point (when no fit is given).
    seed : int
        Base of all seeds (renders and the sampler).
    reweight : bool
        Evaluate the likelihood from path-length recordings when every sampled parameter
        reweights (glass absorption, environment scale, sensor): the two fixed seeds' renders
        are then made once per view, and every evaluation reweights them (docs/sampling.md).
    """

    spp: int = 512
    downsample: int = 2
    clamp: float | None = None
    walkers: int = 0
    max_steps: int = 5000
    max_renders: int | None = None
    ball: float = 0.5
    check_every: int = 20
    noise_renders: int = 8
    calibration_pairs: int = 8
    predictive_draws: int = 8
    eval_spp: int | None = None
    fit_iterations: int = 10
    fit_refinement_steps: int = 3
    seed: int = 0
    reweight: bool = True

    def __post_init__(self):
        if (self.spp < 1 or self.downsample < 1 or self.max_steps < 1 or self.walkers < 0
                or self.noise_renders < 2 or self.calibration_pairs < 0):
            raise InputError(None, "settings", "spp, downsample and max_steps must be >= 1, "
                                               "walkers, calibration_pairs >= 0, noise_renders >= 2")
        if self.walkers and self.walkers % 2:
            raise InputError(None, "walkers", f"must be even (emcee moves half the ensemble at a "
                                              f"time), got {self.walkers}")

    def n_walkers(self, n_scalars: int) -> int:
        w = self.walkers or max(8, 4 * n_scalars)
        if w < 2 * n_scalars:
            raise InputError(None, "walkers", f"need at least {2 * n_scalars} walkers for "
                                              f"{n_scalars} scalars, got {w}")
        return w + w % 2


@dataclass
class SampleResult:
    """What sampling found; :meth:`summary` is ``summary.json``."""

    names: tuple[str, ...]
    sizes: tuple[int, ...]
    units: tuple[str, ...]
    labels: list[str]
    chain: np.ndarray            # (S, W, P) after burn-in, physical units
    log_prob: np.ndarray         # (S, W)
    progress: EnsembleProgress
    burn_in: int
    start: dict[str, dict]       # the fit: name -> {"value": [...], "stderr": [...]}
    noise: NoiseModel
    reduced_chi2: float
    renders: int
    wall_s: float
    settings: SampleSettings
    r_hat: np.ndarray | None = None
    predictive: list[PredictiveView] = field(default_factory=list, repr=False)
    truth: dict[str, list] | None = None
    posterior: RenderPosterior | None = field(default=None, repr=False)
    mode: np.ndarray | None = None  # where the walkers started (the likelihood's mode)
    scene_checks: list[str] = field(default_factory=list)  # the scene's geometry (abs.render.contacts)

    def summary(self) -> dict:
        tau = self.progress.tau if self.progress.tau is not None else np.full(len(self.labels), np.nan)
        parameters = parameter_summary(self.chain, self.names, self.sizes, self.units, tau)
        offset = 0
        for name, n in zip(self.names, self.sizes):
            entry = parameters[name]
            if self.r_hat is not None:
                entry["r_hat"] = self.r_hat[offset:offset + n].tolist()
            entry["fit"] = self.start[name]
            if self.mode is not None:
                entry["mode"] = self.mode[offset:offset + n].tolist()
            if self.truth and name in self.truth:
                entry["truth"] = list(self.truth[name])
            offset += n
        clean = json.loads(json.dumps(parameters, default=float).replace("NaN", "null"))
        summary = {
            "parameters": clean,
            "labels": self.labels,
            "tau": {k: _finite(v) for k, v in zip(self.labels, tau)},
            "r_hat": (None if self.r_hat is None
                      else {k: _finite(v) for k, v in zip(self.labels, self.r_hat)}),
            "acceptance_fraction": self.progress.acceptance_fraction,
            "walkers": int(self.chain.shape[1]),
            "steps": self.progress.steps,
            "burn_in": self.burn_in,
            "samples": int(self.chain.shape[0] * self.chain.shape[1]),
            "converged": self.progress.converged,
            "stop_reason": self.progress.stop_reason,
            "evaluations": self.progress.evaluations,
            "renders": self.renders,
            "wall_s": round(self.wall_s, 3),
            "noise": {**self.noise.to_dict(), "reduced_chi2_at_mode": self.reduced_chi2},
            "likelihood": "crossed Gaussian of two fixed-seed renders recentred on further seed "
                          "pairs, variance = photograph + render_scale x render / 2 "
                          "(docs/sampling.md)",
            "spp": self.settings.spp,
            "downsample": self.settings.downsample,
        }
        return {**summary, "checks": [*self.scene_checks, *run_checks(summary)]}


def _finite(v) -> float | None:
    return float(v) if np.isfinite(v) else None


def read_start(fit_json: str | Path, names) -> dict[str, dict]:
    """Values and standard errors of ``names`` from a ``fit.json``.

    Raises
    ------
    InputError
        If the file is unreadable or lacks a parameter.
    """
    path = Path(fit_json)
    if path.is_dir():
        path = path / "fit.json"
    parameters = read_json(path, what="fit.json").get("parameters")
    if not isinstance(parameters, dict):
        raise InputError(path, "parameters", "missing or not an object: not a fit.json written by "
                                             "abs fit")
    out = {}
    for name in names:
        entry = parameters.get(name)
        if not isinstance(entry, dict) or "value" not in entry:
            raise InputError(path, f"parameters.{name}", "missing: fit this parameter first")
        value = np.atleast_1d(np.asarray(entry["value"], np.float64))
        stderr = entry.get("stderr") or [None] * value.size
        out[name] = {"value": value.tolist(),
                     "stderr": [None if s is None else float(s) for s in stderr]}
    return out


def _fit_start(scene, capture, names, settings: SampleSettings,
               stage: Callable[[str], None]) -> dict[str, dict]:
    from abs.fitting import FitSettings, fit

    def on_iteration(state) -> None:
        loss = state.history[-1]["loss"]  # None: a trial whose renders were not finite
        stage(f"starting fit, iteration {state.iteration} "
              f"(RMSE {'of a non-finite trial' if loss is None else format(loss, '.4g')})")

    result = fit(scene, capture, names, FitSettings(
        spp=settings.spp, downsample=settings.downsample, clamp=settings.clamp,
        max_iterations=settings.fit_iterations, refinement_steps=settings.fit_refinement_steps,
        seed=settings.seed, reweight=settings.reweight), on_iteration=on_iteration)
    parameters = result.summary()["parameters"]
    return {n: {"value": parameters[n]["value"], "stderr": parameters[n]["stderr"]} for n in names}


def _identity(scene, capture, names, settings: SampleSettings) -> dict:
    # Only the settings the likelihood depends on: a longer chain or more walkers' worth of
    # checks continues the same run.
    return run_identity(scene, capture, names, settings,
                        keep=("spp", "downsample", "clamp", "seed", "reweight"))


def _write_meta(path: Path, identity: dict, noise: NoiseModel, start: dict,
                offset: np.ndarray | None, mode: np.ndarray) -> None:
    with h5py.File(path, "a") as f:
        if _GROUP in f:
            del f[_GROUP]
        g = f.create_group(_GROUP)
        g.attrs["identity"] = json.dumps(identity)
        g.attrs["start"] = json.dumps(start)
        g["photo_variance"] = noise.photo_variance
        g["mode"] = mode
        g.attrs["render_scale"] = float(noise.render_scale)
        g.attrs["render_pairs"] = int(noise.render_pairs)
        if noise.correlation is not None:
            g["noise_correlation"] = noise.correlation
        if offset is not None:
            g["residual_offset"] = offset
        for k, v in enumerate(noise.render_variance):
            g[f"render_variance_{k}"] = v


def _read_meta(path: Path, identity: dict) -> tuple[NoiseModel, dict, np.ndarray | None,
                                                    np.ndarray | None]:
    try:
        with h5py.File(path, "r") as f:
            g = f[_GROUP]
            saved = json.loads(g.attrs["identity"])
            start = json.loads(g.attrs["start"])
            n = len(g["photo_variance"])
            noise = NoiseModel(np.asarray(g["photo_variance"]),
                               [np.asarray(g[f"render_variance_{k}"]) for k in range(n)],
                               render_scale=float(g.attrs.get("render_scale", 1.0)),
                               render_pairs=int(g.attrs.get("render_pairs", 1)),
                               correlation=(np.asarray(g["noise_correlation"])
                                            if "noise_correlation" in g else None))
            offset = np.asarray(g["residual_offset"]) if "residual_offset" in g else None
            if offset is not None and offset.ndim == 1:
                # Older chain files kept one offset for both renders: continue them with the
                # likelihood they were sampled with.
                offset = np.stack([offset, offset])
            mode = np.asarray(g["mode"]) if "mode" in g else None
    except (OSError, KeyError, json.JSONDecodeError) as exc:
        raise InputError(path, _GROUP, f"not an abs chain file ({exc}); delete it to start over") from None
    check_identity(path, _GROUP, saved, identity, "chain was sampled",
                   "use another --out folder or drop --resume")
    return noise, start, offset, mode


def _estimate_noise(problem, theta: np.ndarray, spp: int, seed: int, n_renders: int) -> NoiseModel:
    """The noise model at the fit ``theta``.

    Render variance per pixel: the sample variance of ``n_renders`` independent renders
    (smoothed; times the squared pixel weights when the capture gives the photographs' noise,
    :attr:`~abs.model.FitProblem.weights`, as the residuals are).
    Photograph variance per view: from the residuals ``rbar`` of the average of two more
    renders, each ``rbar^2 - var_render / 2`` is an unbiased estimate of it (sensor noise plus any
    model error the fit cannot remove); their weighted mean, weights ``1 / (var_photo +
    var_render / 2)^2`` (iterated from Immerkaer's estimate), so that the few pixels with heavy
    Monte-Carlo noise (caustics, glass) do not swamp it; scaled by ``M / (M - P)`` for the fitted
    scalars.
    """
    from abs.model.noise import estimate_image_noise

    r_bar = 0.5 * (problem.residuals(theta, spp, seed)[0] + problem.residuals(theta, spp, seed + 1)[0])
    dof = r_bar.size / max(r_bar.size - theta.size, 1)
    photo, renders, immerkaer, offset = [], [], [], 0
    for k, obs in enumerate(problem.observations):
        variance = render_variance([problem.render(obs, theta, spp, seed + 2 + n_renders * k + i)
                                    for i in range(n_renders)])
        # In the residuals' units: weighted when the capture gives the photographs' noise.
        if problem.weights is not None:
            variance = variance * np.square(problem.weights[k])
        renders.append(variance)
        immerkaer.append(estimate_image_noise(obs.photograph, obs.camera))
        n = 3 * obs.pixels
        half_render = renders[-1][obs.mask].ravel() / 2
        excess = np.square(r_bar[offset:offset + n]) - half_render
        offset += n
        variance = max(immerkaer[-1] ** 2, 1e-12)
        for _ in range(4):
            weight = 1.0 / np.square(variance + half_render)
            variance = max(float(np.sum(weight * excess) / np.sum(weight)) * dof, 1e-12)
        photo.append(variance)
    correlation = None
    if any(obs.camera.footprint is not None for obs in problem.observations):
        correlation = np.array([np.ones(3) if obs.camera.footprint is None else
                                obs.camera.film().correlate(
                                    np.ones((obs.camera.width * obs.camera.height, 3, 1)))[..., 0]
                                .mean(axis=0) for obs in problem.observations])
    return NoiseModel(np.array(photo), renders, np.array(immerkaer), correlation=correlation)


def _initial_walkers(posterior, theta: np.ndarray, stderr: np.ndarray, walkers: int,
                     ball: float, rng: np.random.Generator) -> np.ndarray:
    """Walkers at ``theta + ball * stderr * N(0, 1)``, redrawn where the prior is zero."""
    out = np.empty((walkers, theta.size))
    for w in range(walkers):
        for _ in range(100):
            candidate = theta + ball * stderr * rng.normal(size=theta.size)
            if np.isfinite(posterior.prior(candidate)):
                break
        else:
            raise InputError(None, "start", f"no start inside the bounds near {theta.tolist()}")
        out[w] = candidate
    return out


def sample(scene, capture, parameters=None, settings: SampleSettings = SampleSettings(),
           chain_path: str | Path = "chain.h5", start: dict[str, dict] | None = None,
           resume: bool = False, pool=None,
           on_step: Callable[[EnsembleProgress], None] | None = None,
           on_stage: Callable[[str], None] | None = None,
           truth: dict[str, list] | None = None, variant: str | None = None) -> SampleResult:
    """Sample the posterior of scene parameters given a capture's training views.

    Parameters
    ----------
    scene : Scene or path
    capture : path
        Capture folder.
    parameters : sequence of str, optional
        Names as in ``abs fit`` (default: the scene's ``[fit] parameters``).
    settings : SampleSettings
    chain_path : path
        The HDF5 chain file (emcee's ``HDFBackend``); replaced unless ``resume``.
    start : dict, optional
        ``name -> {"value": [...], "stderr": [...]}`` (e.g. :func:`read_start` of a fit.json);
        default: run ``abs.fit`` first.
    resume : bool
        Continue the chain in ``chain_path`` (refused if it belongs to another problem).
    pool : object with ``map``, optional
        From :func:`abs.pools.worker_pool`.
    on_step : callable, optional
        Called with an :class:`EnsembleProgress` after every step.
    on_stage : callable, optional
        Called with a short description of each preparation stage before the chain (starting
        fit, noise model, mode search, seed-pair calibration; minutes on a real capture) and of
        the posterior predictive renders after it.
    truth : dict, optional
        Known true values, copied into the summary.
    variant : str, optional
        Mitsuba variant of worker processes (default: this process's).

    Returns
    -------
    SampleResult
    """
    import mitsuba as mi

    from abs.model import build_model

    t0 = time.perf_counter()
    stage = on_stage or (lambda message: None)
    chain_path = Path(chain_path)
    model = build_model(scene, capture, parameters, reweight=settings.reweight)
    scene, names, vector = model.scene, model.names, model.vector
    capture = model.capture.folder
    problem = model.problem("train", settings.downsample, settings.clamp)
    identity = _identity(scene, capture, names, settings)
    resuming = resume and chain_path.exists()
    if resuming:
        noise, start, offset, mode = _read_meta(chain_path, identity)
    else:
        chain_path.unlink(missing_ok=True)
        start = start or _fit_start(scene, capture, names, settings, stage)
    theta_fit = np.concatenate([np.asarray(start[n]["value"], np.float64) for n in names])
    if theta_fit.size != vector.size:
        raise InputError(None, "start", f"{theta_fit.size} values for {vector.size} scalars of {names}")
    masks = [o.mask for o in problem.observations]
    prior = LogPrior.from_vector(vector, {n: p for n, p in scene.fit_priors.items() if n in names})
    seeds = (settings.seed + 1, settings.seed + 2)

    def posterior_with(noise: NoiseModel, offset: np.ndarray | None = None) -> RenderPosterior:
        posterior = RenderPosterior(scene, str(capture), tuple(names), settings.spp,
                                    settings.downsample, seeds, noise.residual_variance(masks),
                                    prior, settings.clamp, variant or mi.variant(), offset,
                                    settings.reweight)
        posterior.adopt(problem)
        return posterior

    stderr = np.concatenate([[np.nan if s is None else s for s in start[n]["stderr"]] for n in names])
    stderr = np.where(np.isfinite(stderr) & (stderr > 0), stderr, 0.1 * vector.step)
    # A resumed chain reports its chi^2 at the mode it started from (older chain files: the fit).
    theta_start = mode if resuming and mode is not None else theta_fit
    if resuming:
        posterior = posterior_with(noise, offset)
    else:
        # The fit (often at fewer samples, or another seed) can sit several posterior standard
        # deviations from the mode of the chain's own fixed-seed likelihood; walkers started
        # there spend the short chains a render budget allows drifting towards it, which biases
        # the kept samples. So: noise model at the fit, Gauss-Newton to the likelihood's mode,
        # the noise model again there (the fit's misfit would inflate the photograph variance),
        # a last step with it, then further seed pairs recentre and calibrate the render noise
        # (abs/sampling/calibration.py) and the mode is found again.
        stage("noise model at the starting point")
        noise = _estimate_noise(problem, theta_fit, settings.spp, settings.seed + 500,
                                settings.noise_renders)
        stage("mode of the likelihood")
        theta_start, _ = find_mode(posterior_with(noise), theta_fit, vector.lower, vector.upper)
        stage("noise model at the mode")
        noise = _estimate_noise(problem, theta_start, settings.spp, settings.seed + 500,
                                settings.noise_renders)
        posterior = posterior_with(noise)
        theta_start, mode_sd = find_mode(posterior, theta_start, vector.lower, vector.upper,
                                         max_steps=2)
        offset = None
        if settings.calibration_pairs:
            stage(f"render-noise calibration ({settings.calibration_pairs} seed pairs)")
            found = calibrate_render_noise(posterior, theta_start, noise.render_part(masks),
                                           settings.calibration_pairs, settings.seed + 700)
            noise = replace(noise, render_scale=found.scale,
                            render_pairs=settings.calibration_pairs + 1)
            offset = found.offset
            posterior = posterior_with(noise, offset)
            theta_start, mode_sd = find_mode(posterior, theta_start, vector.lower, vector.upper,
                                             max_steps=2)
        stderr = np.where(np.isfinite(mode_sd) & (mode_sd > 0), mode_sd, stderr)
        mode = theta_start
    r_a, r_b = posterior.residuals(theta_start)
    reduced_chi2 = float(np.mean(np.square((r_a + r_b) / 2) / posterior.variance))

    walkers = settings.n_walkers(vector.size)
    # From path-length recordings the chain renders nothing: the two seeds' recordings were made
    # with the mode (worker processes of a pool make their own once, uncounted).
    recorded = problem.uses_recordings
    per_eval = 0 if recorded else 2 * len(problem.observations)
    max_evaluations = (None if settings.max_renders is None or recorded
                       else settings.max_renders // per_eval)
    initial = None
    if not resuming:
        _write_meta(chain_path, identity, noise, start, offset, mode)
        initial = _initial_walkers(posterior, theta_start, stderr, walkers, settings.ball,
                                   np.random.default_rng(settings.seed))
    backend = emcee.backends.HDFBackend(str(chain_path))
    if resuming and backend.shape[1] != vector.size:
        raise InputError(chain_path, "mcmc", f"chain has {backend.shape[1]} scalars, not {vector.size}")
    renders_before = problem.counter.renders
    stage("chain")
    progress = run_ensemble(posterior, backend, initial, settings.max_steps, max_evaluations,
                            pool=pool, seed=settings.seed, check_every=settings.check_every,
                            on_step=on_step)

    renders_during = problem.counter.renders  # in-process chain renders, counted below instead
    burn = burn_in(progress.tau, progress.steps)
    chain = backend.get_chain(discard=burn)
    log_prob = backend.get_log_prob(discard=burn)
    from abs.sampling.inference_data import inference_data, r_hat

    sizes = vector.sizes
    rhat = r_hat(inference_data(chain, names, sizes), names) if chain.shape[0] >= 4 else None
    stage(f"posterior predictive ({settings.predictive_draws} draws)")
    predictive = posterior_predictive(model, chain, settings.predictive_draws,
                                      settings.eval_spp or scene.render.spp, settings.seed + 900,
                                      settings.clamp)
    renders = (problem.counter.renders if recorded else
               renders_before + problem.counter.renders - renders_during + progress.evaluations * per_eval)
    return SampleResult(tuple(names), sizes, vector.units, vector.labels(), chain, log_prob, progress,
                        burn, start, noise, reduced_chi2, renders, time.perf_counter() - t0,
                        settings, rhat, predictive, truth, posterior, mode,
                        [c.message() for c in coincident_surfaces(model.compiled)])
