"""A last step along the objective itself, for parameters whose derivative is a central difference.

A parameter that moves what is seen through glass (an IOR) takes its Jacobian column by central
differences of step ``h`` (:mod:`abs.model.difference_steps`): the secant slope over
``[p - h, p + h]``. Where the image is far from linear over that range (a checkerboard's edges
seen through a sphere move by pixels over 0.02 in IOR) the secant is not the derivative, and the
fit's fixed point ``E[J_h^T r] = 0`` need not be the objective's minimum wherever the model does
not reproduce the photographs exactly: the glass suite's clear sphere fitted IOR 1.47205 for
1.47 (2.8 standard errors) at steps 0.02 and 0.04 alike, while the objective itself, evaluated
around the fit, is smallest at 1.4697 (``benchmarks/glass_ior_objective.py``).

:func:`polish` takes that last step without the derivative. For each such scalar it evaluates
the objective at the fitted value and ``offset`` either side (``offset`` a fifth of the
parameter's difference step: the parabola must see the objective's own curvature, not the
image's nonlinearity over the secant), as

- the **two-seed objective** ``r_A . r_B / 2`` (Levenberg-Marquardt's): its expectation is the
  noise-free objective, whereas one render's ``|r|^2`` adds the render variance, which changes
  with the parameter and would move the vertex;
- with **common random numbers** across the offsets (the same two seeds at each), so that the
  differences between offsets carry little of the renders' noise,

with the other scalars held. The vertex of the parabola through the mean of ``pairs`` such
seed pairs' objectives is the minimum along that scalar alone; the photographs' covariance
(the fit's Laplace part) turns it into the joint minimum (:func:`joint_step`: the step times
``1 / (1 - R^2)``, the others moved by their regression on the scalar). The vertices of the
single pairs scatter by the estimate's Monte-Carlo error, which replaces the optimiser's for that
scalar (:func:`polished_monte_carlo_covariance`).

Why not profile the others instead (refit the absorption and scale at every offset from the
pair's own path-length recordings, which renders nothing more)? On the glass suite's 1.52
sphere it ended where holding them does; on its clear sphere, whose absorption sits at its bound
0, the profile left the bound on one side (a kink no parabola follows) and put the absorption at
0.018 per metre, hundreds of its standard errors from 0. Holding them works for any fit, also
one whose other scalars need renders.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abs.fitting.checks import at_bound

__all__ = ["LinePolish", "polish", "joint_step", "polished_monte_carlo_covariance",
           "OFFSET_FRACTION", "POLISH_PAIR", "MAX_AMPLIFICATION"]

#: The parabola's offsets either side, as a fraction of the parameter's difference step.
OFFSET_FRACTION = 0.2
#: Number of the first seed pair (:func:`~abs.fitting.optimisers.lm.pair_seeds`) the polish
#: renders with: clear of Levenberg-Marquardt's (0) and the recordings' pairs (1 on).
POLISH_PAIR = 500


@dataclass(frozen=True)
class LinePolish:
    """One scalar's last step along the objective (``fit.json``'s ``polish`` entries).

    Attributes
    ----------
    name : str
        The parameter (``glass.ior``).
    component : int
        The scalar within it (0 for a tied IOR).
    start, value : float
        The value before the polish (the optimiser's, or where an earlier polish of another
        channel moved it) and after it (physical units).
    offset : float
        The offsets either side of ``start`` the objective was evaluated at (physical units).
    spp : int
        Samples per pixel of the polish's renders.
    vertices : tuple of float
        The vertex of each seed pair's parabola along this scalar alone (physical units; ``nan``,
        ``null`` in ``fit.json``, where it opens downwards).
    monte_carlo_stderr : float
        Standard error of ``value`` from the pairs' scatter, times ``amplification`` (``nan``
        with fewer than two convex pairs, or when ``note`` says the value is not the vertex).
    slopes : dict of str to list of float
        By parameter name, how its scalars moved per unit of this one (the photographs'
        regression, :func:`joint_step`); parameters that stayed are left out.
    amplification : float
        The joint step over the step along this scalar alone (:func:`joint_step`; 1: none).
    note : str or None
        Why the value is not the vertex: the parabola opens downwards (kept), the vertex lies
        beyond twice the offset (moved that far only: the optimiser had not converged), or the
        bounds leave no room for the offsets (kept).
    propagation : ndarray or None
        The step's map of the optimiser's error (:func:`joint_step`); not in ``fit.json``.
    """

    name: str
    component: int
    start: float
    value: float
    offset: float
    spp: int
    vertices: tuple[float, ...]
    monte_carlo_stderr: float
    slopes: dict
    amplification: float = 1.0
    note: str | None = None
    propagation: np.ndarray | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """``fit.json``'s entry (public contract, docs/fitting.md)."""
        stderr = self.monte_carlo_stderr
        return {"name": self.name, "component": self.component, "start": self.start,
                "value": self.value, "offset": self.offset, "spp": self.spp,
                "vertices": [v if np.isfinite(v) else None for v in self.vertices],
                "monte_carlo_stderr": None if not np.isfinite(stderr) else stderr,
                "slopes": self.slopes, "amplification": self.amplification, "note": self.note}


def _vertex(offset: float, values: np.ndarray) -> float:
    """Vertex of the parabola through the objective's ``values`` at ``-offset, 0, offset``,
    relative to the middle (``nan`` when it opens downwards)."""
    curvature = (values[0] - 2.0 * values[1] + values[2]) / offset ** 2
    slope = (values[2] - values[0]) / (2.0 * offset)
    return -slope / curvature if curvature > 0 else float("nan")


def polish(objective, z: np.ndarray, spp: int, pairs: int, seed: int = 0,
           steps: dict | None = None, covariance: np.ndarray | None = None,
           identifiable: np.ndarray | None = None) -> tuple[np.ndarray, list[LinePolish]]:
    """Polish every scalar of ``objective`` whose derivative is a central difference.

    Parameters
    ----------
    objective : Objective
        The fit's objective (its problem: views, resolution, pixel weights, priors).
    z : ndarray
        The optimiser's estimate (unconstrained coordinates).
    spp : int
        Samples per pixel of the polish's renders.
    pairs : int
        Seed pairs averaged (each renders two images per view at three offsets).
    seed : int
        The fit's seed.
    steps : dict, optional
        Difference steps by parameter name (the pilot's choice); default: each parameter's own.
    covariance : ndarray, shape (P, P), optional
        The photographs' covariance of the estimate (the Laplace part, physical units): turns the
        minimum along one scalar, the others held, into the joint minimum (:func:`joint_step`).
        Without it the others stay.
    identifiable : ndarray of bool, shape (P,), optional
        Scalars the covariance resolves (the Laplace approximation's); the others stay.

    Returns
    -------
    z : ndarray
        The polished estimate.
    polishes : list of LinePolish
        One per polished scalar (empty when no parameter takes central differences).
    """
    from abs.fitting.optimisers.lm import pair_seeds, two_seed_value

    vector, compiled = objective.vector, objective.model.compiled
    z = np.array(z, np.float64)
    # Inside the open bounds (a value on a bound has no unconstrained coordinate).
    finite_bounds = np.nan_to_num(np.stack([vector.lower, vector.upper]), posinf=0.0, neginf=0.0)
    margin = 1e-9 * np.maximum(1.0, np.abs(finite_bounds).max(axis=0))
    done = []
    for name, where in vector.slices().items():
        spec = compiled.specs[name]
        if spec.difference_step is None:
            continue
        offset = OFFSET_FRACTION * float((steps or {}).get(name, spec.difference_step))
        for component, index in enumerate(range(where.start, where.stop)):
            theta = vector.to_physical(z)
            start = float(theta[index])
            # Stay inside the parameter's bounds (an IOR near 1 cannot go below it).
            room = min(offset, start - vector.lower[index] - margin[index],
                       vector.upper[index] - margin[index] - start)
            if not room > 0.0:
                done.append(LinePolish(name, component, start, start, 0.0, spp, (), float("nan"), {},
                                       note="no room for the offsets within the bounds: kept"))
                continue
            values = np.zeros((pairs, 3))
            for k in range(pairs):
                pair_seed = pair_seeds(seed, POLISH_PAIR + k)[0]
                for j, o in enumerate((-room, 0.0, room)):
                    point = np.array(theta)
                    point[index] = start + o
                    values[k, j] = two_seed_value(objective, vector.to_unconstrained(point), pair_seed, spp)
            vertices = np.array([_vertex(room, v) for v in values])
            vertex = _vertex(room, values.mean(axis=0))
            note = None
            if not np.isfinite(vertex):
                note = "the objective is not convex over the offsets: kept the optimiser's value"
                vertex = 0.0
            elif abs(vertex) > 2.0 * room:
                note = (f"the objective's vertex lies {vertex:+.4g} away, beyond twice the offset: "
                        "moved twice the offset only (the optimiser had not converged)")
                vertex = float(np.clip(vertex, -2.0 * room, 2.0 * room))
            held = np.array([at_bound(float(t), float(lo), float(hi)) is not None
                             for t, lo, hi in zip(theta, vector.lower, vector.upper)])
            if identifiable is not None:
                held |= ~np.asarray(identifiable, bool)
            amplification, slope, propagation = joint_step(covariance, index, held)
            moved = slope != 0.0
            new = np.array(theta)
            new[moved] = np.clip(theta[moved] + amplification * vertex * slope[moved],
                                 vector.lower[moved] + margin[moved], vector.upper[moved] - margin[moved])
            z = vector.to_unconstrained(new)
            convex = vertices[np.isfinite(vertices)]
            # Only a value at the vertex is the polish's estimate: a kept or clipped one keeps
            # the optimiser's Monte-Carlo error (polished_monte_carlo_covariance).
            stderr = (float(amplification * np.std(convex, ddof=1) / np.sqrt(len(convex)))
                      if len(convex) >= 2 and note is None else float("nan"))
            # Every scalar that moved with it, its own parameter's other channels included.
            slopes = {n: [float(x) for x in slope[s]] for n, s in vector.slices().items()
                      if vertex != 0.0 and np.any(moved[s] & (np.arange(s.start, s.stop) != index))}
            done.append(LinePolish(name, component, start, float(new[index]), float(room), spp,
                                   tuple(float(start + v) for v in vertices), stderr, slopes,
                                   float(amplification), note, propagation))
    return z, done


#: The joint step is at most this many times the step along the scalar alone (a scalar whose
#: multiple correlation with the others exceeds 0.95 is barely identified: the photographs do
#: not tell where along the ridge the minimum lies).
MAX_AMPLIFICATION = 10.0


def joint_step(covariance: np.ndarray | None, index: int,
               held: np.ndarray) -> tuple[float, np.ndarray, np.ndarray | None]:
    """How the joint minimum moves when scalar ``index``'s minimum with the others held moves by 1.

    For a quadratic objective with curvature ``H`` (``covariance^-1``), from a point where the
    other scalars minimise it for the current value of scalar ``i``, the minimum along ``i``
    alone lies ``-g_i / H_ii`` away and the joint minimum ``-g_i S`` along ``i``, with ``S`` the
    covariance of ``i`` given the ``held`` scalars (those stay: at a bound, where the objective
    has a kink, or not resolved): the step along ``i`` alone times ``H_ii S = 1 / (1 - R^2)``,
    ``R`` the multiple correlation of ``i`` with the moving others, which move by their
    regression on ``i`` (``S_oi / S_ii`` per unit of ``i``).

    Returns
    -------
    amplification : float
        ``H_ii S_ii`` (1 without a covariance; at most :data:`MAX_AMPLIFICATION`).
    direction : ndarray, shape (P,)
        1 at ``index``, the regression slopes for the moving others, 0 for the held ones.
    propagation : ndarray, shape (P, P) or None
        ``A`` with ``x' - x* = A (x - x*)`` for the step from ``x`` (the optimiser's error in,
        the polished estimate's out; its own Monte-Carlo error aside): ``I - S[:, i] H[i, :]``
        over the moving scalars, identity on the held ones; ``None`` without a covariance
        (then the step only sets scalar ``i``: see :func:`polished_monte_carlo_covariance`).
    """
    n = len(held)
    direction = np.zeros(n)
    direction[index] = 1.0
    if covariance is None:
        return 1.0, direction, None
    covariance = np.asarray(covariance, np.float64)
    diagonal = np.diag(covariance)
    resolved = np.isfinite(diagonal) & (diagonal > 0) & np.all(np.isfinite(covariance), axis=1)
    if not resolved[index]:
        return 1.0, direction, None
    keep = np.flatnonzero(resolved)
    try:
        precision = np.linalg.inv(covariance[np.ix_(keep, keep)])
    except np.linalg.LinAlgError:
        return 1.0, direction, None
    moving = np.flatnonzero(~held[keep] | (keep == index))  # positions within keep
    H = precision[np.ix_(moving, moving)]  # the curvature over the moving scalars
    try:
        S = np.linalg.inv(H)  # their covariance given the held ones
    except np.linalg.LinAlgError:
        return 1.0, direction, None
    at = int(np.flatnonzero(keep[moving] == index)[0])
    amplification = float(np.clip(H[at, at] * S[at, at], 1.0, MAX_AMPLIFICATION))
    rows = keep[moving]
    direction[rows] = S[:, at] / S[at, at]
    direction[index] = 1.0
    # With the amplification as used (clipped or not): x' = x - (amplification / H_ii) u g_i.
    propagation = np.eye(n)
    propagation[np.ix_(rows, rows)] -= (amplification / H[at, at]) * np.outer(direction[rows], H[at, :])
    return amplification, direction, propagation


def polished_monte_carlo_covariance(extra: np.ndarray, vector, polishes: list[LinePolish]) -> np.ndarray:
    """The estimate's Monte-Carlo covariance after the polish.

    ``extra`` is the optimiser's (the refinement's scatter, :func:`~abs.fitting.laplace.
    with_monte_carlo_error`). Each polish maps the optimiser's error through its
    ``propagation`` (:func:`joint_step`: near the minimum the step removes the error's component
    along the polished scalar, wherever the optimiser left it) and adds its own: the pairs'
    scatter along the direction it moved (the scalar, and the others by their slopes). Without a
    propagation (no covariance given) the polished scalar's row and column are replaced by the
    polish's. A polish without a standard error (one pair, fewer than two convex parabolas, or a
    value kept or clipped rather than at the vertex) leaves the optimiser's share as it was.
    """
    out = np.array(extra, np.float64)
    slices = vector.slices()
    for p in polishes:
        if not np.isfinite(p.monte_carlo_stderr):
            continue
        i = slices[p.name].start + p.component
        if p.propagation is not None:
            out = p.propagation @ out @ p.propagation.T
        else:
            out[i, :] = 0.0
            out[:, i] = 0.0
        u = np.zeros(vector.size)
        for name, slope in p.slopes.items():
            u[slices[name]] = slope
        u[i] = 1.0
        out += p.monte_carlo_stderr ** 2 * np.outer(u, u)
    return out
