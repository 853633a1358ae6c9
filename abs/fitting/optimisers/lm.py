"""``lm``: Levenberg-Marquardt, then a Gauss-Newton refinement on decorrelated renders.

- :func:`levenberg_marquardt`: Levenberg-Marquardt on the two-seed objective ``r_A . r_B / 2``
  of two fixed-seed renders (common random numbers: deterministic), with the renderer's
  forward-mode Jacobians. Its expectation is the noise-free objective, whereas that of one
  render's ``|r_A|^2`` adds the render variance, which depends on the parameters (a brighter
  scene is noisier) and pulls the minimum towards darker renderings. Second order: few
  iterations, each costing about ``2 (1 + P)`` renders per view; the choice when the parameter
  count ``P`` is small.
- :func:`gauss_newton_refinement`: after Levenberg-Marquardt, a few Gauss-Newton steps whose
  residuals and Jacobian come from independent renders with fresh seeds: they average out the
  two fixed seeds' own noise. The refinement's fixed point, ``E[J_B^T r_A] = 0``, is unbiased; its
  curvature comes from two independent Jacobians (:func:`cross_curvature`) so the steps are not
  shortened by the Jacobian noise, pooled over steps so that one pair's noise cannot throw a
  step anywhere; its steps grow while they keep pointing the same way (the unbiased solution can
  be many typical steps away); once it has arrived, every step's Newton target under the pooled
  curvature estimates the solution: their mean is the estimate and their scatter the
  Monte-Carlo part of the standard errors.

Both phases are one optimiser because the refinement starts where Levenberg-Marquardt stopped
and a resumed fit must know which phase it was in (:class:`LMState`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from abs.fitting.optimisers import Callback, Optimiser, OptimizerState, register

__all__ = ["LevenbergMarquardt", "LMState", "RefinementState", "levenberg_marquardt",
           "gauss_newton_refinement", "recording_pairs", "free_refit", "pair_seeds", "two_seed_value",
           "cross_curvature", "column_scale", "averaged_refinement_points", "lm_stages"]


@dataclass(frozen=True, eq=False)
class RefinementState:
    """The Gauss-Newton refinement so far.

    Attributes
    ----------
    points : tuple of ndarray
        The points ``z`` stepped to (unconstrained, typical steps), in order.
    clipped : tuple of bool
        Per point: reached while still travelling (a step clipped to the trust radius in the
        previous step's direction, or a coordinate whose steps have not yet turned back).
    radius : ndarray or None
        The trust radius of every coordinate (typical steps); ``None`` before the first step.
    step : ndarray or None
        The last step, to tell whether the next one turns back.
    limited : tuple of tuple of bool
        Per point, per coordinate: the Gauss-Newton step to it was larger than the coordinate's
        trust radius (and was clipped). A coordinate limited at nearly every step is moved by the
        renders' noise, not by the photographs (:meth:`LevenbergMarquardt.limited_steps`). Empty in
        checkpoints from before it was kept.
    curvatures : tuple of ndarray
        Per step, the cross curvature ``(J1^T J2 + J2^T J1) / 2`` (P, P; unconstrained
        coordinates) of its two independent Jacobians, unfloored, and ``curvature_at`` the
        point ``z`` they were rendered at: the Laplace approximation averages those of the
        steps whose points are averaged (:meth:`LevenbergMarquardt.curvatures`). Empty in
        checkpoints from before they were kept.
    gradients, scales : tuple of ndarray
        Per step, the gradient ``(J1 + J2)^T r / 2`` at ``curvature_at`` and the Jacobians'
        :func:`column_scale`: with the curvatures they give the steps' Newton targets under the
        pooled curvature (:func:`newton_targets`). Empty in checkpoints from before they were
        kept (the estimate is then the mean of the points).
    """

    points: tuple = ()
    clipped: tuple = ()
    radius: np.ndarray | None = None
    step: np.ndarray | None = None
    limited: tuple = ()
    curvatures: tuple = ()
    curvature_at: tuple = ()
    gradients: tuple = ()
    scales: tuple = ()


@dataclass(frozen=True, eq=False)
class LMState:
    """What the ``lm`` optimiser remembers between iterations (and across a resume).

    Attributes
    ----------
    converged : bool or None
        Levenberg-Marquardt's verdict once it has finished (``None``: not yet).
    refinement : RefinementState
    pairs : bool
        The refinement's points are one Newton step from the solution per seed pair of
        path-length recordings (:func:`recording_pairs`), not Gauss-Newton iterates.
    """

    converged: bool | None = None
    refinement: RefinementState = RefinementState()
    pairs: bool = False

    def to_dict(self) -> dict:
        # Keys as checkpoints have always had them (the state was a dictionary once).
        out = {}
        if self.converged is not None:
            out["lm_converged"] = self.converged
        if self.pairs:
            out["recording_pairs"] = True
        r = self.refinement
        if r.points:
            out.update(refinement=[np.asarray(p).tolist() for p in r.points],
                       refinement_clipped=list(r.clipped),
                       refinement_radius=None if r.radius is None else np.asarray(r.radius).tolist(),
                       refinement_step=None if r.step is None else np.asarray(r.step).tolist())
            if r.limited:  # absent from checkpoints written before it was kept
                out["refinement_limited"] = [list(map(bool, row)) for row in r.limited]
            if r.curvatures:
                out["refinement_curvatures"] = [np.asarray(h).tolist() for h in r.curvatures]
                out["refinement_curvature_at"] = [np.asarray(z).tolist() for z in r.curvature_at]
            if r.gradients:
                out["refinement_gradients"] = [np.asarray(g).tolist() for g in r.gradients]
                out["refinement_scales"] = [np.asarray(c).tolist() for c in r.scales]
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "LMState":
        points = tuple(np.asarray(p, np.float64) for p in d.get("refinement", []))
        step = d.get("refinement_step")
        radius = d.get("refinement_radius")
        refinement = RefinementState(points,
                                     tuple(bool(c) for c in d.get("refinement_clipped",
                                                                  [False] * len(points))),
                                     # One radius for every coordinate in older checkpoints.
                                     None if radius is None else np.asarray(radius, np.float64),
                                     None if step is None else np.asarray(step, np.float64),
                                     tuple(tuple(bool(c) for c in row)
                                           for row in d.get("refinement_limited", [])),
                                     tuple(np.asarray(h, np.float64)
                                           for h in d.get("refinement_curvatures", [])),
                                     tuple(np.asarray(z, np.float64)
                                           for z in d.get("refinement_curvature_at", [])),
                                     tuple(np.asarray(g, np.float64)
                                           for g in d.get("refinement_gradients", [])),
                                     tuple(np.asarray(c, np.float64)
                                           for c in d.get("refinement_scales", [])))
        converged = d.get("lm_converged")
        return cls(None if converged is None else bool(converged), refinement,
                   bool(d.get("recording_pairs", False)))


@register("lm")
class LevenbergMarquardt(Optimiser):
    """Levenberg-Marquardt on two fixed-seed renders, then ``refinement_steps`` Gauss-Newton
    steps on fresh, independent renders (see the module docstring).

    Uses the settings ``max_iterations``, ``rtol``, ``atol``, ``refinement_steps``, ``seed`` and
    ``downsample_schedule`` (coarse-to-fine stages, :func:`lm_stages`).
    """

    State = LMState

    def run(self, objective, state: OptimizerState, settings,
            on_iteration: Callback | None = None) -> OptimizerState:
        solver = state.solver or LMState()
        # A resumed fit continues Levenberg-Marquardt unless it converged or refinement began.
        if not solver.converged and not solver.refinement.points:
            free = objective.free.size > 0
            for factor, end in lm_stages(settings):
                if state.iteration >= end:
                    continue
                state = levenberg_marquardt(
                    lambda z, iteration, f=factor: _two_renders(objective, z, settings.seed, f),
                    state, end, settings.rtol, settings.atol, on_iteration,
                    refit=(lambda z, f=factor: free_refit(objective, z, settings.seed, f,
                                                          settings.rtol, settings.atol))
                    if free else None)
                if end < settings.max_iterations:
                    state.solver = replace(state.solver, converged=None)  # a coarse stage
            if state.solver is not None and state.solver.converged and on_iteration is not None:
                # Once more, so that a checkpoint knows: a resumed fit must not run
                # Levenberg-Marquardt again where it had converged (it would evaluate again).
                on_iteration(state)

        def fresh(z, iteration):  # independent seeds for r, J1 and J2 at every refinement step
            base, spp = settings.seed + 10_000 * iteration, settings.refinement_spp
            r, J1, loss = objective.residuals(z, base + 1, base + 2, spp=spp)
            return r, (J1, objective.jacobian(z, base + 3, spp=spp)), loss

        if objective.reweighted:
            return recording_pairs(objective, state, settings, on_iteration)
        return gauss_newton_refinement(fresh, state, settings.refinement_steps,
                                       on_iteration=on_iteration)

    def averaged_points(self, state: OptimizerState) -> np.ndarray | None:
        solver = state.solver or LMState()
        refinement = solver.refinement
        if not refinement.points:
            return None
        if solver.pairs:  # one point per independent seed pair, all of them
            return np.asarray(refinement.points, np.float64)
        targets = newton_targets(refinement)
        if targets is not None:
            return targets
        return averaged_refinement_points(refinement.points, refinement.clipped)

    def scatter_points(self, state: OptimizerState) -> np.ndarray | None:
        solver = state.solver or LMState()
        refinement = solver.refinement
        if not refinement.points:
            return None
        if solver.pairs:
            return np.asarray(refinement.points, np.float64)
        # All but the first quarter, arrived or not; targets where the estimate is theirs.
        if _target_steps(refinement) is not None:
            return newton_targets(refinement, arrived_only=False)
        return averaged_refinement_points(refinement.points)

    def sequential_points(self, state: OptimizerState) -> bool:
        """Gauss-Newton iterates are sequential (a clipped step walks); the points of recording
        pairs are independent, and so, nearly, are the refinement's Newton targets (each from its
        own renders; they share only the pooled curvature)."""
        solver = state.solver or LMState()
        return not solver.pairs and _target_steps(solver.refinement) is None

    def curvatures(self, state: OptimizerState) -> tuple[np.ndarray, np.ndarray] | None:
        """The refinement's cross curvatures (K, P, P) and the points ``z`` (K, P) they were
        rendered at, for the steps after the first quarter (those of :meth:`scatter_points`):
        each an unbiased estimate of ``J^T J`` near the solution, from renders as independent as
        the final Laplace approximation's pair. ``None`` without Gauss-Newton steps or their
        record."""
        solver = state.solver or LMState()
        refinement = solver.refinement
        n = len(refinement.points)
        if solver.pairs or n < 2 or len(refinement.curvatures) != n:
            return None
        start = max(1, n // 4)
        return (np.asarray(refinement.curvatures[start:], np.float64),
                np.asarray(refinement.curvature_at[start:], np.float64))

    def limited_steps(self, state: OptimizerState) -> np.ndarray | None:
        """Per refinement step after the first quarter (the steps to :meth:`scatter_points`),
        per coordinate: whether the Gauss-Newton step was larger than the trust radius.

        A measured coordinate's Newton steps from fresh renders scatter around the solution by
        about a typical step and are clipped now and then (at most half of the steps in the glass
        suite's spheres); one whose steps are clipped nearly every time is moved by the renders'
        Monte-Carlo noise (its curvature from two noisy Jacobians is noise, so the step is
        arbitrarily long): the refinement walks at random in it, and the walk's scatter is no
        measure of its error (the bowl of the glass suite: IOR 1.733 +- 0.014 for 1.52, 10 of 11
        steps clipped). Steps reached while still travelling count too, although the averaged
        points leave them out: a coordinate clipped at nearly every step is not measured either
        way (still travelling when the refinement ended, or walking at random). ``None`` without
        Gauss-Newton steps or their record.
        """
        solver = state.solver or LMState()
        refinement = solver.refinement
        n = len(refinement.points)
        if solver.pairs or n < 2 or len(refinement.limited) != n:
            return None
        return np.asarray(refinement.limited, bool)[max(1, n // 4):]


def recording_pairs(objective, state: OptimizerState, settings,
                    on_iteration: Callback | None = None) -> OptimizerState:
    """The refinement of a fit whose renders all come from path-length recordings.

    Levenberg-Marquardt's two-seed solution has two Monte-Carlo errors that the Gauss-Newton
    refinement removes with fresh renders at every step. Its scatter: on the default scene at
    160x120 and 16 spp a glass absorption's solution scattered by 2 per metre between seed pairs,
    fifteen times its Laplace error (which sees the average pixel noise, not that the glass's few
    pixels are far noisier). And a bias of order ``1 / spp``: the objective's gradient is unbiased
    at every point, but its minimiser is not quite, because one pair's curvature and gradient
    share that pair's noise. Both shrink as ``1 / K`` when the objective is averaged over ``K``
    independent pairs (a solution per pair would keep the bias), and from recordings that costs
    only their
    recordings: Levenberg-Marquardt minimises the mean two-seed objective of pair 0 (the first
    solve) and ``refinement_steps`` further pairs, stacked as one pair of residual vectors scaled
    by ``1 / sqrt(K)``. Its remaining Monte-Carlo error is measured by the pairs' own gradients
    ``g_k`` at the solution: the points ``z - H^-1 g_k`` (``H`` the joint cross curvature), whose
    mean is the solution and whose covariance over ``K`` is ``H^-1 cov(g) H^-1 / K``
    (:meth:`averaged_points`, added to the Laplace covariance).
    """
    solver = replace(state.solver or LMState(), pairs=True)
    if solver.refinement.points:  # finished before a resume
        state.solver = solver
        return state
    seeds = [pair_seeds(settings.seed, k)[0] for k in range(settings.refinement_steps + 1)]
    if len(seeds) == 1:
        state.solver = solver
        return state

    def pairs(z):
        return [_two_renders(objective, z, seed, settings.downsample) for seed in seeds]

    def stack(parts):
        scale = 1.0 / np.sqrt(len(parts))
        stacked = [tuple(np.concatenate([p[side][i] for p in parts]) * scale for i in (0, 1))
                   for side in (0, 1)]
        return stacked[0], stacked[1], float(np.mean([p[2] for p in parts]))

    inner = levenberg_marquardt(lambda z, iteration: stack(pairs(z)),
                                OptimizerState(state.method, 0, np.array(state.z, np.float64)),
                                settings.max_iterations, settings.rtol, settings.atol)
    for entry in inner.history:
        state.iteration += 1
        state.history.append({**entry, "iteration": state.iteration, "phase": f"{len(seeds)} pairs"})
    z = np.array(inner.z, np.float64)
    parts = pairs(z)
    (_, Ja), (_, Jb), _ = stack(parts)
    H = cross_curvature(Ja, Jb)
    points = [z - np.linalg.solve(H, 0.5 * (pa[1].T @ pb[0] + pb[1].T @ pa[0]))
              for pa, pb, _ in parts]
    # Centred on the solution: their mean is z up to the joint gradient left at convergence.
    points = [p - (np.mean(points, axis=0) - z) for p in points]
    solver = replace(solver, refinement=RefinementState(tuple(points), (False,) * len(points)))
    state.solver = solver
    state.z = z
    if on_iteration is not None:
        on_iteration(state)
    return state


def pair_seeds(seed: int, pair: int) -> tuple[int, int]:
    """The two render seeds of Levenberg-Marquardt's seed pair number ``pair`` (0: the first
    solve; :func:`recording_pairs` numbers the further ones), for a fit seeded ``seed``: ``+7``
    apart and ``20 000`` per pair, clear of the other seeds a fit uses."""
    base = seed + 20_000 * pair
    return base, base + 7


def _two_renders(objective, z, seed: int, factor: int, names=None):
    """Residuals and Jacobians of the two renders of the pair starting at ``seed``
    (:func:`pair_seeds`), and their mean RMSE; ``names`` restricts the Jacobians' columns."""
    ra, Ja, la = objective.residuals(z, seed, factor=factor, names=names)
    rb, Jb, lb = objective.residuals(z, seed + 7, factor=factor, names=names)
    return (ra, Ja), (rb, Jb), 0.5 * (la + lb)


def two_seed_value(objective, z, seed: int, spp: int | None = None) -> float:
    """The two-seed objective ``r_A . r_B / 2`` (weighted residuals with the priors' rows) of
    the pair starting at ``seed`` (:func:`pair_seeds`) at the objective's resolution, without
    Jacobians; ``spp``: samples per pixel (default: the objective's)."""
    ra = objective.weighted_residuals(z, seed, spp=spp)
    rb = objective.weighted_residuals(z, seed + 7, spp=spp)
    return 0.5 * float(ra @ rb)


#: Evaluations of one refit of the free scalars (:func:`free_refit`); each renders nothing.
FREE_REFIT_ITERATIONS = 20


def free_refit(objective, z: np.ndarray, seed: int, factor: int, rtol: float = 1e-4,
               atol: float = 1e-6) -> np.ndarray:
    """``z`` with its free scalars (:attr:`Objective.free`: absorption, environment scale, sensor)
    moved to the minimum of the two-seed objective over them, the others (IOR, pose) held.

    Those scalars reweight the path-length recordings made at the others' values, so this
    renders nothing beyond the two recordings per view that evaluating the objective at ``z``
    needs anyway: Levenberg-Marquardt then works on the profile of the objective over the
    parameters that move paths (variable projection), and the reweightable parameters no longer
    cost an outer iteration's renders to settle after every change of the IOR.
    """
    free = objective.free
    names = objective.problem(factor).reweightable

    def evaluate(z_free, iteration):
        point = np.array(z, np.float64)
        point[free] = z_free
        (ra, Ja), (rb, Jb), loss = _two_renders(objective, point, seed, factor, names)
        return (ra, Ja[:, free]), (rb, Jb[:, free]), loss

    inner = levenberg_marquardt(evaluate, OptimizerState("lm", 0, np.array(z, np.float64)[free]),
                                FREE_REFIT_ITERATIONS, rtol, atol)
    out = np.array(z, np.float64)
    out[free] = inner.z
    return out


def lm_stages(settings) -> list[tuple[int, int]]:
    """Levenberg-Marquardt's coarse-to-fine stages: ``(downsampling factor, last evaluation)``.

    ``settings.downsample_schedule`` as for Adam: ``((0, 4), (8, 1))`` compares box-averaged
    images (factor 4) from evaluation 0 and full images from evaluation 8, up to
    ``max_iterations``; empty: one stage at ``settings.downsample``. The refinement that follows
    compares at ``settings.downsample``. Why: a checkerboard seen through glass moves by more than
    a square when the IOR is 0.02 off, and a Gauss-Newton model of the sharp image then predicts
    nothing (its steps shrink to thousandths); averaged images stay near-linear over a wider
    range, so coarse stages find the basin and the fine stage the minimum.
    """
    stages = sorted((start, factor) for start, factor in settings.downsample_schedule
                    if start < settings.max_iterations)
    if not stages:
        return [(settings.downsample, settings.max_iterations)]
    if stages[0][0] > 0:
        stages.insert(0, (0, settings.downsample))
    ends = [start for start, _ in stages[1:]] + [settings.max_iterations]
    return [(factor, end) for (_, factor), end in zip(stages, ends)]


#: Levenberg-Marquardt's largest step per coordinate, in typical steps (see the transforms of
#: :class:`~abs.model.parameters.ParameterVector`).
MAX_STEP = 2.0


def levenberg_marquardt(evaluate: Callable[[np.ndarray, int], tuple],
                        state: OptimizerState, max_iterations: int, rtol: float = 1e-4,
                        atol: float = 1e-6, on_iteration: Callback | None = None,
                        refit: Callable[[np.ndarray], np.ndarray] | None = None) -> OptimizerState:
    """Levenberg-Marquardt on the two-seed objective ``f(z) = r_A(z) . r_B(z) / 2``.

    ``r_A`` and ``r_B`` are the weighted residuals of two renders with different, fixed seeds
    (common random numbers within each: ``f`` is a deterministic function of ``z``). Why not
    ``|r_A|^2 / 2``, the classical least-squares objective of one fixed-seed render: its
    expectation adds the renders' Monte-Carlo variance, and that variance depends on the
    parameters (a glass with more absorption is darker and less noisy), so its minimum sits in
    the wrong place. On glass before a checkerboard at 64 spp the variance term was five times
    the change of the loss over the IOR's whole basin, and Levenberg-Marquardt on one render
    ended at IOR 1.50 and absorption 8/10/16 per metre for a truth of 1.62 and 2/5/9. ``f``'s
    expectation is the noise-free objective exactly (the two renders' noises are independent),
    so its minimiser has no such bias.

    ``f`` is not a sum of squares, so this is Levenberg-Marquardt written out (optimistix's
    solvers, which abs used before, take residual functions only): the model
    ``f + g.d + d.H.d / 2`` with the exact gradient ``g = (J_A^T r_B + J_B^T r_A) / 2`` and the
    cross curvature ``H`` of the two Jacobians (:func:`cross_curvature`, the Gauss-Newton
    curvature without the Jacobians' noise); steps ``(H + lambda S) d = -g`` (``S``: each
    column's own squared size, :func:`column_scale`), at most ``MAX_STEP`` typical steps per
    coordinate; a trial is accepted when ``f`` falls by at least a thousandth of the predicted
    fall, and ``lambda`` follows Nielsen's rule.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(z, iteration) -> ((r_A, J_A), (r_B, J_B), loss)``: the two renders'
        residuals (M,) and Jacobians (M, P) w.r.t. ``z``, and the loss to report.
    state : OptimizerState
        Start (a resumed run restarts the damping at its last accepted point).
    max_iterations : int
        Last evaluation (counted in ``state.iteration``; each trial point is one).
    rtol, atol : float
        Stop when every coordinate of a step is below ``atol + rtol |z|`` (typical steps).
    refit : callable, optional
        ``refit(z) -> z``, applied to every point before it is evaluated (:func:`free_refit`:
        the scalars that render nothing moved to their best values at the point's others); a
        trial is judged by the objective at the refitted point.
    """
    if state.iteration >= max_iterations:
        return state
    z = np.array(state.z, np.float64)

    def at(point):
        if refit is not None:
            point = refit(point)
        state.iteration += 1
        (ra, Ja), (rb, Jb), loss = evaluate(point, state.iteration)
        if not all(np.all(np.isfinite(a)) for a in (ra, rb, Ja, Jb)):
            # A trial point whose renders or derivatives are not finite is a failed step (the
            # damping grows), not the end of the fit: measured once in a 64-spp full-resolution
            # fit of a box's pose with a cloth lobe, where eigh of the curvature then failed.
            state.history.append({"iteration": state.iteration, "loss": None, "objective": None,
                                  "z": list(map(float, point)), "non_finite": True})
            return np.inf, None, (None, None), point
        f = 0.5 * float(ra @ rb)
        g = 0.5 * (Ja.T @ rb + Jb.T @ ra)
        state.history.append({"iteration": state.iteration, "loss": float(loss), "objective": f,
                              "z": list(map(float, point))})
        return f, g, (cross_curvature(Ja, Jb), column_scale(Ja, Jb)), point

    f, g, (H, scale), z = at(z)
    if not np.isfinite(f):
        raise FloatingPointError(f"the renders or their derivatives at the fit's start are not finite "
                                 f"(z = {list(map(float, z))})")
    state.z = z
    if on_iteration is not None:
        on_iteration(state)
    damping, growth, converged = 1e-3, 2.0, False
    while state.iteration < max_iterations:
        step = np.linalg.solve(H + damping * np.diag(scale), -g)
        # At most MAX_STEP typical steps per coordinate: far from the solution the quadratic
        # model can ask for a leap that the objective accepts, into a region a bounded transform
        # flattens (glass absorption thrown to 0 through softplus, whose gradient then vanishes:
        # the bowl of the glass suite stayed at 0, 0, 43 per metre). Per coordinate, not by
        # shortening the whole step: that held the environment scale at 1.01 for twenty
        # evaluations while absorption asked for a leap.
        step = np.clip(step, -MAX_STEP, MAX_STEP)
        if np.all(np.abs(step) <= atol + rtol * np.abs(z)):
            converged = True
            break
        predicted = -float(g @ step + 0.5 * step @ H @ step)
        f_trial, g_trial, curvature_trial, trial = at(z + step)
        ratio = (f - f_trial) / predicted if predicted > 0 else -np.inf  # f_trial = inf: -inf
        if ratio > 1e-3:
            z, f, g, (H, scale) = trial, f_trial, g_trial, curvature_trial
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
            growth = 2.0
        else:
            damping *= growth
            growth *= 2.0
        state.z = z
        if on_iteration is not None:
            on_iteration(state)
        if damping > 1e8:  # no step along any direction lowers f: a (noisy) minimum
            converged = True
            break
    state.solver = replace(state.solver or LMState(), converged=converged)
    return state


def cross_curvature(J1: np.ndarray, J2: np.ndarray) -> np.ndarray:
    """Unbiased estimate of ``J^T J`` from two independent noisy Jacobians, made positive definite.

    ``E[J1^T J1] = Jbar^T Jbar + Cov`` overstates the curvature by the Jacobian's Monte-Carlo
    covariance; ``(J1^T J2 + J2^T J1) / 2`` has expectation ``Jbar^T Jbar`` exactly. Its noise can
    make small eigenvalues negative: they are raised as :func:`floored_curvature` says.
    """
    return floored_curvature(0.5 * (J1.T @ J2 + J2.T @ J1), column_scale(J1, J2))


def floored_curvature(H: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``H`` (P, P; symmetric) with eigenvalues raised to 1e-3 of the largest, in the matrix
    scaled to unit column sizes ``scale`` (:func:`column_scale`): the columns' sizes differ by
    orders (an environment scale moves every pixel, an absorption the glass's few), and a floor
    relative to the unscaled matrix's largest eigenvalue had raised glass absorption's curvature
    fivefold, so that every step went a fifth of the way."""
    size = np.sqrt(np.maximum(scale, 1e-300))
    w, V = np.linalg.eigh(H / np.outer(size, size))
    w = np.maximum(w, 1e-3 * max(float(w.max()), 1e-300))
    return (V * w) @ V.T * np.outer(size, size)


#: A pooled curvature's diagonal is kept at least this many of its standard errors.
CURVATURE_FLOOR_SE = 2.0
#: A Newton target lies at most this many of its coordinate's trust radii from its point.
TARGET_RADII = 4.0
#: Newton targets need at least this many averaged steps: the curvature's floor needs three.
MIN_TARGET_STEPS = 3


def pooled_curvature(curvatures, scales) -> np.ndarray:
    """The mean of several steps' cross curvatures (unfloored, each ``(J1^T J2 + J2^T J1) / 2``),
    its diagonal kept at least :data:`CURVATURE_FLOOR_SE` standard errors of itself (from three
    steps on) and floored at the mean column scale (:func:`floored_curvature`).

    One pair's cross curvature of a column that is mostly noise (an IOR seen through a thin
    glass wall before the checkerboard: its column's noise ten times its signal at 64 spp) can
    be any size, and the Newton step it gives any length; the mean of ``K`` pairs has a ``K``
    times smaller variance, while the curvature itself changes little between nearby points.
    Where the mean is still within noise of zero (rare large jumps in the column: its pairs'
    products scatter more than their mean), its inverse is not an estimate of anything, and the
    floor keeps a Newton step from it no longer than the noise allows.
    """
    curvatures = np.asarray(curvatures, np.float64)
    H = np.mean(curvatures, axis=0)
    if len(curvatures) >= 3:
        diagonal = np.diagonal(curvatures, axis1=1, axis2=2)
        floor = CURVATURE_FLOOR_SE * diagonal.std(axis=0, ddof=1) / np.sqrt(len(curvatures))
        H = H + np.diag(np.maximum(floor - np.diag(H), 0.0))
    return floored_curvature(H, np.mean(np.asarray(scales, np.float64), axis=0))


def column_scale(J1: np.ndarray, J2: np.ndarray) -> np.ndarray:
    """Mean squared size of each Jacobian column over the two Jacobians: each coordinate's own
    scale, noise included (what Levenberg-Marquardt's damping and the curvature floor are
    measured in, so that a column that is mostly noise is still damped at its own size)."""
    return 0.5 * (np.sum(J1 ** 2, axis=0) + np.sum(J2 ** 2, axis=0))


def _turned_back(points: list) -> bool:
    """Whether every coordinate's step has changed sign at least once along ``points``: until
    then some coordinate is still travelling towards the solution (its steps all point one way,
    as glass absorption's did for ten steps from a Levenberg-Marquardt start 5 per metre off),
    and averaging its points would stop it short."""
    if len(points) < 3:
        return False
    signs = np.sign(np.diff(np.asarray(points, np.float64), axis=0))
    return bool(np.all(np.any(signs[1:] != signs[:-1], axis=0)))


def _averaged_steps(n: int, travelling: list | None = None) -> range:
    """Indices of the refinement points :func:`averaged_refinement_points` averages."""
    start = max(1, n // 4)
    if travelling is not None and any(travelling):
        start = max(start, max(i for i, t in enumerate(travelling) if t) + 1)
    return range(start, n) if start < n else range(max(n - 1, 0), n)


def _target_steps(refinement: RefinementState, arrived_only: bool = True) -> range | None:
    """The steps :func:`newton_targets` uses, or ``None`` when it gives none (its docstring):
    whether the estimate is the targets', without solving for them."""
    n = len(refinement.points)
    if n == 0 or not (len(refinement.gradients) == len(refinement.scales)
                      == len(refinement.curvatures) == len(refinement.curvature_at) == n):
        return None
    steps = _averaged_steps(n, refinement.clipped if arrived_only else None)
    return steps if len(steps) >= MIN_TARGET_STEPS else None


def newton_targets(refinement: RefinementState, arrived_only: bool = True) -> np.ndarray | None:
    """The refinement's estimates of the solution, one per averaged step: ``z_k - H^-1 g_k``,
    each step's gradient ``g_k`` at the point ``z_k`` it was rendered at, under the curvature
    ``H`` pooled over those steps (:func:`pooled_curvature`).

    Near the solution ``E[g_k] = H (z_k - z*)``, so every target estimates ``z*`` and their mean
    averages the gradients' noise; a step's own point (``z_k`` plus its clipped Newton step)
    carries its own curvature's noise as well, which for a noisy column (the framed bowl's IOR)
    made the points walk by 0.02 to 0.03 in the IOR per step. ``arrived_only``: leave out the
    steps :func:`averaged_refinement_points` leaves out (those reached while still travelling);
    otherwise all but the first quarter. ``None`` when the record is incomplete (a checkpoint
    from before gradients were kept) or fewer than :data:`MIN_TARGET_STEPS` steps are averaged:
    the pooled curvature's floor needs three, and without it one or two pairs' curvature of a
    column that is mostly noise puts its targets anywhere within their clip (in the test's model
    of rare large jumps, two steps' estimate missed that coordinate by 1.9 RMS, the points by
    0.5).
    """
    steps = _target_steps(refinement, arrived_only)
    if steps is None:
        return None
    H = pooled_curvature([refinement.curvatures[i] for i in steps], [refinement.scales[i] for i in steps])
    # A coordinate the images do not see (an absorption deep at its bound 0: its column and
    # gradient vanish together) has a curvature of numerical dust, and its Newton step is
    # arbitrary: the glass suite's distant bowl got targets that overflowed a float. No target
    # lies further from its point than TARGET_RADII trust radii (typical steps), as the walk's
    # own steps do not.
    reach = TARGET_RADII * (np.ones(H.shape[0]) if refinement.radius is None
                            else np.asarray(refinement.radius, np.float64))
    targets = []
    for i in steps:
        with np.errstate(all="ignore"):
            step = -np.linalg.solve(H, refinement.gradients[i])
        targets.append(refinement.curvature_at[i] + np.clip(np.nan_to_num(step, nan=0.0), -reach, reach))
    return np.array(targets)


def averaged_refinement_points(points: list, travelling: list | None = None) -> np.ndarray:
    """The refinement points that are averaged: all but the first quarter (at least the first
    one), which may still be travelling from the biased start, and none reached while travelling
    (``travelling``, one flag per point, which :func:`gauss_newton_refinement` clears for good
    once the walk has arrived); full Newton steps usually arrive within a step or two, after
    which the points scatter independently around the unbiased solution. When every step was
    clipped, the last point alone."""
    points = np.asarray(points, np.float64)
    return points[list(_averaged_steps(len(points), travelling))]


def gauss_newton_refinement(evaluate: Callable[[np.ndarray, int], tuple],
                            state: OptimizerState, steps: int, max_step: float = 1.0,
                            on_iteration: Callback | None = None) -> OptimizerState:
    """Gauss-Newton steps on decorrelated renders; returns the mean of the steps' Newton targets
    under their pooled curvature (:func:`newton_targets`) once the walk has arrived.

    Each step solves ``H dz = -g`` with ``g = (J1 + J2)^T r / 2`` and ``H`` the cross curvature
    of two independent Jacobians (:func:`cross_curvature`), pooled over the more recent half of
    the steps so far (:func:`pooled_curvature`): with ``r``, ``J1`` and ``J2`` from three
    independent renders both are unbiased, so the step is the full Newton step on the expected
    objective rather than one shortened by the Jacobian noise (which, with ``J1^T J1``, took a
    third of the way per step at 16 spp on an IOR), and pooling keeps one pair's noisy
    curvature from throwing the step anywhere.

    Steps are clipped coordinate by coordinate to trust radii (in typical steps) that start at
    ``max_step``: a noisy Jacobian must not throw the fit far from the Levenberg-Marquardt
    solution. A coordinate's radius doubles when its clipped step is followed by one of the same
    sign (the solution lies further than the radius, not noise: Levenberg-Marquardt's fixed-seed
    objective can sit many typical steps from it when the renders' Monte-Carlo variance changes
    with the parameters, as for a BRDF's specular lobe or a glass's absorption), and halves, down
    to ``max_step``, when its step turns back. Per coordinate, because one noisy coordinate (an IOR
    seen through glass before a checkerboard) turning back at every step held a single shared
    radius at its floor and stopped the others from travelling (glass absorption moved 0.4 per
    metre per step towards a solution 5 per metre away).

    Parameters
    ----------
    evaluate : callable
        ``evaluate(z, iteration) -> (r, (J1, J2), loss)`` with independent fresh seeds for ``r``,
        ``J1`` and ``J2`` at every call.
    steps : int
        Number of steps (each costs one evaluation).
    max_step : float
        Initial and smallest trust radius (typical steps).
    """
    solver = state.solver or LMState()
    saved = solver.refinement
    points = [np.asarray(p, np.float64) for p in saved.points]
    travelling = list(saved.clipped) if saved.clipped else [False] * len(points)
    # A refinement resumed from a checkpoint without the record keeps none (not a partial one).
    limited = list(saved.limited) if len(saved.limited) == len(points) else None
    kept = len(saved.curvatures) == len(points) == len(saved.curvature_at)
    curvatures = list(saved.curvatures) if kept else None
    curvature_at = list(saved.curvature_at) if kept else None
    kept = kept and len(saved.gradients) == len(points) == len(saved.scales)
    gradients = list(saved.gradients) if kept else None
    scales = list(saved.scales) if kept else None
    # The curvatures the steps pool (this run's alone after a checkpoint without them).
    pool = list(zip(saved.curvatures, saved.scales)) if kept else []
    radius = np.full(np.size(state.z), float(max_step))
    if saved.radius is not None:
        radius = np.broadcast_to(np.asarray(saved.radius, np.float64), radius.shape).copy()
    previous = saved.step
    z = points[-1] if points else np.array(state.z, np.float64)
    # A clipped coordinate's step equals its radius (how a resumed refinement knows).
    clipped_before = (np.zeros(radius.shape, bool) if previous is None
                      else np.abs(np.asarray(previous, np.float64)) >= radius * (1 - 1e-9))
    while len(points) < steps:
        state.iteration += 1
        r, (J1, J2), loss = evaluate(z, state.iteration)
        state.history.append({"iteration": state.iteration, "loss": float(loss),
                              "z": list(map(float, z)), "phase": "refinement"})
        cross, scale, gradient = 0.5 * (J1.T @ J2 + J2.T @ J1), column_scale(J1, J2), 0.5 * (J1 + J2).T @ r
        if curvatures is not None:
            curvatures.append(cross)
            curvature_at.append(np.array(z, np.float64))
        if gradients is not None:
            gradients.append(gradient)
            scales.append(scale)
        pool.append((cross, scale))
        recent = pool[len(pool) // 2:]
        step = np.linalg.solve(pooled_curvature(*zip(*recent)), -gradient)
        if previous is not None:
            same = np.sign(step) == np.sign(np.asarray(previous, np.float64))
            radius = np.where(clipped_before & same, 2.0 * radius,
                              np.where(~same, np.maximum(max_step, radius / 2.0), radius))
        clipped_before = np.abs(step) > radius
        # Travelling: a clipped step that keeps the previous step's direction, or a coordinate
        # that has not yet turned back. Once arrived, the walk stays arrived: later clipped
        # steps are noise around the solution (full Newton steps on fresh renders scatter by a
        # typical step or more at 64 spp through glass), and flagging them had left only the
        # last point to average when one of five coordinates was clipped twice in a row there.
        onward = clipped_before if previous is None else clipped_before & same
        step = np.clip(step, -radius, radius)
        z = z + step
        points.append(z)
        arrived = bool(travelling) and not travelling[-1]
        travelling.append(not arrived and (bool(onward.any()) or not _turned_back(points)))
        if limited is not None:
            limited.append(tuple(map(bool, clipped_before)))
        previous = step
        solver = replace(solver, refinement=RefinementState(tuple(points), tuple(travelling),
                                                            radius.copy(), step,
                                                            tuple(limited or ()),
                                                            tuple(curvatures or ()),
                                                            tuple(curvature_at or ()),
                                                            tuple(gradients or ()),
                                                            tuple(scales or ())))
        state.solver = solver
        targets = newton_targets(solver.refinement)
        state.z = np.mean(targets if targets is not None
                          else averaged_refinement_points(points, travelling), axis=0)
        if on_iteration is not None:
            on_iteration(state)
    return state
