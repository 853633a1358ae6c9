"""A full BRDF table from a few observed entries, by regularised least squares on the PCA basis.

Nielsen et al. (2015): with x' the mapped observed values and Q', x̄' the rows of the basis at the
observed entries,

    c = (Q'ᵀQ' + ηI)⁻¹ Q'ᵀ (x' − x̄'),        table = unmap(x̄ + Qc).

**Choice of η.** The formula is the posterior mean of c under the model x' − x̄' = Q'c + e with
e ~ N(0, s²I) per entry and the prior c ~ N(0, τ²I); then η = s²/τ², and both variances are known
from the training set rather than tuned:

- τ² is the variance of the training materials' coefficients (1/(m − 1) for the scaled
  eigenvectors Q = VΣ of m centred tables: the rows of U);
- s² is the variance of what the basis cannot represent in an unseen material, per mapped entry
  (the leave-one-out residual :attr:`BRDFBasis.residual_variance`, computed when the basis is
  built), plus the variance of the measurement noise in the mapped domain (``noise``: the
  relative standard deviation of the observed BRDF values; the mapping is a logarithm, so a
  relative error σ becomes an absolute error of at most σ).

So η grows with the truncation error and the noise and shrinks towards 0 for a basis that
explains unseen materials well: with many observations the data dominate, with few the prior
keeps the coefficients at the size seen in the training set instead of letting them explode.
"""

from __future__ import annotations

import numpy as np

from abs.brdf.basis import BRDFBasis, map_brdf
from abs.io.merl import MERL_SIZE

__all__ = ["default_eta", "coefficient_prior_variance", "fit_coefficients", "reconstruct", "project_table"]

_CHUNK = 1 << 18


def default_eta(basis: BRDFBasis, noise: float = 0.0) -> float:
    """η = s²/τ² (see the module docstring).

    Parameters
    ----------
    basis : BRDFBasis
        A basis with ``residual_variance`` and ``training_coefficients`` (made by
        :func:`abs.brdf.pca.build_basis`).
    noise : float
        Relative standard deviation of the observed BRDF values (dimensionless, e.g. 0.05).

    Returns
    -------
    float
        η (dimensionless, mapped units² per coefficient variance).
    """
    if basis.residual_variance is None or basis.training_coefficients is None:
        raise ValueError("this basis has no training-set statistics (residual_variance, "
                         "training_coefficients); pass eta explicitly")
    return (basis.residual_variance + noise**2) / coefficient_prior_variance(basis)


def coefficient_prior_variance(basis: BRDFBasis) -> float:
    """τ², the variance of the training materials' coefficients (1/(m − 1) for m centred tables):
    the prior variance of an unseen material's coefficients."""
    if basis.training_coefficients is None:
        raise ValueError("this basis has no training_coefficients (the prior's variance τ²); "
                         "build it with abs.brdf.pca.build_basis")
    return float(np.mean(np.var(basis.training_coefficients.astype(np.float64), axis=0, ddof=1)))


def _observations(entries: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    entries = np.asarray(entries).reshape(-1)
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if not np.issubdtype(entries.dtype, np.integer):
        raise ValueError(f"entries must be integer table indices, got dtype {entries.dtype}")
    if entries.size != values.size or entries.size == 0:
        raise ValueError(f"need as many values as entries (> 0), got {values.size} and {entries.size}")
    if entries.min() < 0 or entries.max() >= MERL_SIZE:
        raise ValueError(f"entries must lie in [0, {MERL_SIZE})")
    if not np.isfinite(values).all():
        raise ValueError("observed values must be finite")
    return entries, values


def fit_coefficients(basis: BRDFBasis, entries: np.ndarray, values: np.ndarray,
                     eta: float | None = None, noise: float = 0.0) -> np.ndarray:
    """Coefficients c from observed table entries (see the module docstring).

    Parameters
    ----------
    basis : BRDFBasis
        The basis.
    entries : np.ndarray
        Flat indices into the (3·90·90·180,) table, e.g. from :func:`abs.brdf.directions.merl_entries`
        (any shape; repeats weigh an entry more).
    values : np.ndarray
        Observed BRDF values at those entries, 1/sr (same number as ``entries``; negative values
        are clipped at 0 before the mapping).
    eta : float, optional
        Regularisation η >= 0; :func:`default_eta` (with ``noise``) when omitted.
    noise : float
        Relative standard deviation of ``values``, used only for the default η.

    Returns
    -------
    np.ndarray
        (K,) float64 coefficients.
    """
    entries, values = _observations(entries, values)
    eta = default_eta(basis, noise) if eta is None else float(eta)
    if not eta >= 0:
        raise ValueError(f"eta must be >= 0, got {eta}")
    x = map_brdf(np.maximum(values, 0.0), basis.median[entries].astype(np.float64),
                 basis.cosine_weight[entries].astype(np.float64), basis.epsilon)
    q = basis.components[:, entries].astype(np.float64)  # (K, n)
    r = x - basis.mean[entries]
    normal = q @ q.T + eta * np.eye(basis.n_components)
    return np.linalg.lstsq(normal, q @ r, rcond=None)[0]


def reconstruct(basis: BRDFBasis, entries: np.ndarray, values: np.ndarray,
                eta: float | None = None, noise: float = 0.0) -> np.ndarray:
    """The full table from observed entries: :func:`fit_coefficients`, then the inverse mapping.

    Returns
    -------
    np.ndarray
        float32 table of shape (3, 90, 90, 180), BRDF in 1/sr, clamped at 0.
    """
    return basis.table(fit_coefficients(basis, entries, values, eta, noise))


def project_table(basis: BRDFBasis, table: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of a complete table (all entries, η = 0): the basis' best
    representation of it in the mapped space, e.g. the truth coefficients of a held-out material.

    Returns
    -------
    np.ndarray
        (K,) float64.
    """
    r = basis.mapped(table) - basis.mean
    k = basis.n_components
    normal, rhs = np.zeros((k, k)), np.zeros(k)
    for start in range(0, MERL_SIZE, _CHUNK):  # float64 sums without a float64 copy of Q
        q = basis.components[:, start:start + _CHUNK].astype(np.float64)
        normal += q @ q.T
        rhs += q @ r[start:start + _CHUNK]
    return np.linalg.solve(normal, rhs)
