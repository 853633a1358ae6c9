"""Where to measure: direction pairs that make a reconstruction from n observations most accurate.

Nielsen et al. (2015) choose sampling directions by optimising how well the observed rows of the
basis condition the reconstruction. Here the criterion comes from the Bayesian model that already
fixes η (:mod:`abs.brdf.reconstruct`): with prior c ~ N(0, τ²I) and per-entry error variance s²,
observing the entries S leaves the coefficients a posterior covariance s²(Q_SᵀQ_S + ηI)⁻¹, so the
expected squared mapped error of the reconstructed table, averaged over direction pairs, is

    E(S) = s² · trace(G (Q_SᵀQ_S + ηI)⁻¹),      G = Σ_e μ_e q_e q_eᵀ / Σ_e μ_e,

with q_e the basis' column at entry e and μ_e the direction-pair measure of the entry
(:func:`abs.brdf.directions.merl_entry_measure`): the error the benchmark reports, in
expectation (the truncation error of the basis itself comes on top and does not depend on S).
This is Bayesian A-optimal design. E does not depend on the measured values, so the directions
can be planned before any measurement.

The mapped error weighs every direction pair alike in log-relative units, so it spends few
measurements on the narrow specular peak, where the reflected radiance is largest. The
``"radiance"`` criterion weighs each entry by the squared change of the cosine-weighted BRDF per
mapped unit, J_e = (median_e·w_e + ε)·exp(x̄_e) at the training mean x̄, relative to the mean
table's cosine-weighted energy:

    G = Σ_e μ_e J_e² q_e q_eᵀ / Σ_e μ_e (w_e f̄_e)²,

so E is the expected squared relative cosine-weighted error ‖w(f̂ − f)‖²/‖wf̄‖² to first order
(the error of renderings, not of the log table). Criteria are registered by name in
:data:`CRITERIA`.

Pairs are chosen greedily from a candidate set (each pair observes three entries, R, G and B:
a rank-3 update of the precision, scored for every candidate at once by the Woodbury identity).
Greedy selection is nested: the first n pairs of a selection of N are the greedy choice for n, so
one run plans every n. It is not guaranteed to find the best set, only a good one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from abs.brdf.basis import BRDFBasis
from abs.brdf.directions import merl_entries, merl_entry_measure, uniform_hemisphere_directions
from abs.brdf.reconstruct import coefficient_prior_variance, default_eta
from abs.io.merl import MERL_SIZE

__all__ = ["DirectionPlan", "plan_directions", "pair_weighted_gram", "expected_error", "CRITERIA"]

_CHUNK = 1 << 18


@dataclass(frozen=True)
class DirectionPlan:
    """Direction pairs to measure, best first.

    Attributes
    ----------
    wi, wo : ndarray, shape (n, 3)
        Unit directions in the local frame (z = normal).
    expected_rmse : ndarray, shape (n,)
        Expected RMSE of the reconstruction from the first 1, 2, …, n pairs, from the basis' own
        error model (``sqrt(E)``; truncation error not included), in the criterion's units:
        log-relative for ``"mapped"``, a fraction of the mean table's cosine-weighted RMS for
        ``"radiance"``.
    criterion : str
        The name in :data:`CRITERIA` the pairs were chosen by.
    """

    wi: np.ndarray
    wo: np.ndarray
    expected_rmse: np.ndarray
    criterion: str = "mapped"


def _mapped_weights(basis: BRDFBasis) -> np.ndarray:
    """μ_e / Σ μ: every direction pair counts alike."""
    measure = merl_entry_measure()
    return measure / measure.sum()


def _radiance_weights(basis: BRDFBasis) -> np.ndarray:
    """μ_e J_e² / Σ μ_e (w_e f̄_e)²: mapped errors converted to cosine-weighted BRDF errors at the
    training mean, relative to the mean table."""
    measure = merl_entry_measure()
    slope = (basis.median.astype(np.float64) * basis.cosine_weight + basis.epsilon) \
        * np.exp(basis.mean.astype(np.float64))                       # d(w·f)/dx at x = x̄
    energy = np.sum(measure * np.maximum(slope - basis.epsilon, 0.0) ** 2)
    return measure * slope ** 2 / energy


#: Per-entry weights a_e of G = Σ_e a_e q_e q_eᵀ, by criterion name (add one to add a criterion).
CRITERIA: dict[str, Callable[[BRDFBasis], np.ndarray]] = {
    "mapped": _mapped_weights,
    "radiance": _radiance_weights,
}


def pair_weighted_gram(basis: BRDFBasis, criterion: str = "mapped") -> np.ndarray:
    """G = Σ_e a_e q_e q_eᵀ (K, K): the basis' second moments averaged over direction pairs
    rather than table entries, weighted by the criterion (:data:`CRITERIA`)."""
    if criterion not in CRITERIA:
        raise ValueError(f"unknown criterion {criterion!r}; known: {', '.join(CRITERIA)}")
    weights = CRITERIA[criterion](basis)
    k = basis.n_components
    gram = np.zeros((k, k))
    for start in range(0, MERL_SIZE, _CHUNK):
        q = basis.components[:, start:start + _CHUNK].astype(np.float64)
        gram += (q * weights[start:start + _CHUNK]) @ q.T
    return gram


def _error_variance(basis: BRDFBasis, eta: float) -> float:
    """s² = η τ² (the per-entry error variance that η stands for)."""
    return eta * coefficient_prior_variance(basis)


def expected_error(basis: BRDFBasis, entries: np.ndarray, eta: float | None = None,
                   gram: np.ndarray | None = None) -> float:
    """E(S) of the module docstring for observed ``entries`` (flat table indices), in the squared
    units of the criterion whose ``gram`` is given (mapped units² by default).

    Parameters
    ----------
    basis : BRDFBasis
        A basis with training-set statistics (made by :func:`abs.brdf.pca.build_basis`).
    entries : ndarray of int
        Observed entries (any shape).
    eta : float, optional
        Default: :func:`abs.brdf.reconstruct.default_eta`.
    gram : ndarray, optional
        :func:`pair_weighted_gram` of ``basis`` (the ``"mapped"`` one when omitted).
    """
    eta = default_eta(basis) if eta is None else float(eta)
    gram = pair_weighted_gram(basis) if gram is None else gram
    q = basis.components[:, np.asarray(entries).reshape(-1)].astype(np.float64)
    precision = q @ q.T + eta * np.eye(basis.n_components)
    return _error_variance(basis, eta) * float(np.trace(np.linalg.solve(precision, gram)))


def plan_directions(basis: BRDFBasis, n: int, candidates: int | tuple[np.ndarray, np.ndarray] = 20_000,
                    eta: float | None = None, max_theta_deg: float = 80.0,
                    rng: np.random.Generator | int | None = 0,
                    criterion: str = "mapped") -> DirectionPlan:
    """Choose ``n`` direction pairs that minimise the expected reconstruction error (greedily).

    Parameters
    ----------
    basis : BRDFBasis
        A basis with training-set statistics (leave the materials you will measure out of it).
    n : int
        Number of direction pairs.
    candidates : int or (wi, wo)
        Either a number of random candidate pairs (ωi, ωo independent and uniform in solid angle on
        the hemisphere up to ``max_theta_deg``) or the pairs your instrument can reach, two
        (C, 3) arrays of directions in the local frame.
    eta : float, optional
        The regularisation the reconstruction will use (default: ``default_eta(basis)``; pass
        ``default_eta(basis, noise)`` for noisy measurements).
    max_theta_deg : float
        Largest polar angle of random candidates, degrees.
    rng : Generator, int or None
        Random candidates' source.
    criterion : str
        What the plan minimises (:data:`CRITERIA`): ``"mapped"``, the expected log-relative error
        of the table, or ``"radiance"``, the expected relative error of the cosine-weighted BRDF
        (what renderings show; it measures more pairs near the specular peak).

    Returns
    -------
    DirectionPlan
    """
    eta = default_eta(basis) if eta is None else float(eta)
    if not eta > 0:
        raise ValueError(f"eta must be > 0 to plan directions (with eta = 0 fewer than K/3 pairs "
                         f"leave the coefficients undetermined), got {eta}")
    if isinstance(candidates, (int, np.integer)):
        rng = np.random.default_rng(rng)
        wi = uniform_hemisphere_directions(rng, int(candidates), np.radians(max_theta_deg))
        wo = uniform_hemisphere_directions(rng, int(candidates), np.radians(max_theta_deg))
    else:
        wi, wo = (np.asarray(a, np.float64).reshape(-1, 3) for a in candidates)
        if wi.shape != wo.shape:
            raise ValueError(f"candidate wi and wo differ in shape: {wi.shape} vs {wo.shape}")
        if not ((wi[:, 2] > 0) & (wo[:, 2] > 0)).all():
            raise ValueError("candidate directions must lie above the horizon (z > 0)")
    if not 1 <= n <= len(wi):
        raise ValueError(f"n must lie in [1, {len(wi)}] (the number of candidates), got {n}")

    gram = pair_weighted_gram(basis, criterion)
    rows = np.moveaxis(basis.components[:, merl_entries(wi, wo)].astype(np.float64), 0, -1)  # (C, 3, K)
    s2 = _error_variance(basis, eta)
    cov = np.eye(basis.n_components) / eta  # (Q_SᵀQ_S + ηI)⁻¹ with S empty
    available = np.ones(len(wi), bool)
    chosen, expected = [], []
    for _ in range(n):
        # Woodbury: adding rows B lowers trace(G·cov) by trace((I + B cov Bᵀ)⁻¹ B cov G cov Bᵀ).
        bc = rows @ cov                                                     # (C, 3, K)
        inner = np.eye(3) + bc @ np.swapaxes(rows, 1, 2)                    # (C, 3, 3)
        outer = bc @ gram @ np.swapaxes(bc, 1, 2)                           # (C, 3, 3)
        gain = np.trace(np.linalg.solve(inner, outer), axis1=1, axis2=2)
        gain[~available] = -np.inf
        best = int(np.argmax(gain))
        cov = cov - bc[best].T @ np.linalg.solve(inner[best], bc[best])
        cov = 0.5 * (cov + cov.T)
        available[best] = False
        chosen.append(best)
        expected.append(s2 * float(np.trace(gram @ cov)))
    index = np.array(chosen)
    return DirectionPlan(wi[index], wo[index], np.sqrt(np.array(expected)), criterion)
