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

Pairs are chosen greedily from a candidate set (each pair observes three entries, R, G and B:
a rank-3 update of the precision, scored for every candidate at once by the Woodbury identity).
Greedy selection is nested: the first n pairs of a selection of N are the greedy choice for n, so
one run plans every n. It is not guaranteed to find the best set, only a good one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.brdf.basis import BRDFBasis
from abs.brdf.directions import merl_entries, merl_entry_measure, uniform_hemisphere_directions
from abs.brdf.reconstruct import coefficient_prior_variance, default_eta
from abs.io.merl import MERL_SIZE

__all__ = ["DirectionPlan", "plan_directions", "pair_weighted_gram", "expected_mapped_error"]

_CHUNK = 1 << 18


@dataclass(frozen=True)
class DirectionPlan:
    """Direction pairs to measure, best first.

    Attributes
    ----------
    wi, wo : ndarray, shape (n, 3)
        Unit directions in the local frame (z = normal).
    expected_rmse : ndarray, shape (n,)
        Expected mapped RMSE (log-relative units) of the reconstruction from the first 1, 2, …, n
        pairs, from the basis' own error model (``sqrt(E)``; truncation error not included).
    """

    wi: np.ndarray
    wo: np.ndarray
    expected_rmse: np.ndarray


def pair_weighted_gram(basis: BRDFBasis) -> np.ndarray:
    """G = Σ_e μ_e q_e q_eᵀ / Σ_e μ_e (K, K): the basis' second moments averaged over direction
    pairs rather than table entries."""
    measure = merl_entry_measure()
    k = basis.n_components
    gram = np.zeros((k, k))
    for start in range(0, MERL_SIZE, _CHUNK):
        q = basis.components[:, start:start + _CHUNK].astype(np.float64)
        gram += (q * measure[start:start + _CHUNK]) @ q.T
    return gram / measure.sum()


def _error_variance(basis: BRDFBasis, eta: float) -> float:
    """s² = η τ² (the per-entry error variance that η stands for)."""
    return eta * coefficient_prior_variance(basis)


def expected_mapped_error(basis: BRDFBasis, entries: np.ndarray, eta: float | None = None,
                          gram: np.ndarray | None = None) -> float:
    """E(S) of the module docstring for observed ``entries`` (flat table indices), mapped units².

    Parameters
    ----------
    basis : BRDFBasis
        A basis with training-set statistics (made by :func:`abs.brdf.pca.build_basis`).
    entries : ndarray of int
        Observed entries (any shape).
    eta : float, optional
        Default: :func:`abs.brdf.reconstruct.default_eta`.
    gram : ndarray, optional
        :func:`pair_weighted_gram` of ``basis`` (computed when omitted).
    """
    eta = default_eta(basis) if eta is None else float(eta)
    gram = pair_weighted_gram(basis) if gram is None else gram
    q = basis.components[:, np.asarray(entries).reshape(-1)].astype(np.float64)
    precision = q @ q.T + eta * np.eye(basis.n_components)
    return _error_variance(basis, eta) * float(np.trace(np.linalg.solve(precision, gram)))


def plan_directions(basis: BRDFBasis, n: int, candidates: int | tuple[np.ndarray, np.ndarray] = 20_000,
                    eta: float | None = None, max_theta_deg: float = 80.0,
                    rng: np.random.Generator | int | None = 0) -> DirectionPlan:
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

    gram = pair_weighted_gram(basis)
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
    return DirectionPlan(wi[index], wo[index], np.sqrt(np.array(expected)))
