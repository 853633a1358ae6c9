"""Building the PCA BRDF basis: Nielsen et al.'s mapping, then PCA through the m×m Gram matrix.

The data matrix X has one row per training material (m ≈ 100) and one column per table entry
(N = 3·90·90·180 ≈ 4.4 M), too large for a direct SVD. Its centred version Xc = UΣVᵀ has the
same left singular vectors and singular values as the small Gram matrix G = Xc·Xcᵀ = UΣ²Uᵀ, so
one eigendecomposition of G (m×m) and one pass over the data give the scaled eigenvectors
Q = VΣ = Xcᵀ·U (stored one row per component). A training table is then exactly
``mean + Qᵀ·U[j]``: the rows of U are the training materials' coefficients, and across the
training set each coefficient has mean 0 and variance 1/(m − 1).

Memory: the m mapped tables are held once as float32 (m·N·4 bytes, 1.6 GB for 95 materials) and
transformed in place; everything else is done in column chunks.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from abs.brdf.basis import BRDFBasis, map_brdf, merl_cosine_weight
from abs.io.merl import MERL_SIZE

__all__ = ["DEFAULT_EPSILON", "GramPCA", "gram_pca", "scaled_components", "loo_residuals", "build_basis"]

DEFAULT_EPSILON = 1e-3
"""ε of the mapping in 1/sr (Nielsen et al. 2015 use 0.001): below it, cosine-weighted values are
compressed instead of log-stretched, so near-black entries do not dominate the PCA."""

_CHUNK = 1 << 17  # columns per chunk: m·_CHUNK float64 temporaries (~100 MB for m = 95)


@dataclass(frozen=True)
class GramPCA:
    """PCA of a centred data matrix Xc (m×n) from its Gram matrix.

    Attributes
    ----------
    mean : np.ndarray
        (n,) float32 column means that were subtracted.
    left : np.ndarray
        (m, m) float64 U: column k is the k-th left singular vector; row j holds material j's
        coefficients.
    singular_values : np.ndarray
        (m,) float64 Σ, descending (the last is 0 up to rounding: centring removes one rank).
    gram : np.ndarray
        (m, m) float64 Xc·Xcᵀ.
    """

    mean: np.ndarray
    left: np.ndarray
    singular_values: np.ndarray
    gram: np.ndarray


def gram_pca(data: np.ndarray, chunk: int = _CHUNK) -> GramPCA:
    """PCA of the rows of ``data`` through the m×m Gram matrix. **Centres ``data`` in place.**

    Parameters
    ----------
    data : np.ndarray
        (m, n) float32 array, one row per sample (material); overwritten by its centred version.
    chunk : int
        Columns per chunk of the float64 accumulation.

    Returns
    -------
    GramPCA
        Mean, U, Σ and the Gram matrix; the scaled eigenvectors follow from
        :func:`scaled_components`.
    """
    m, n = data.shape
    mean = np.empty(n, np.float32)
    gram = np.zeros((m, m), np.float64)
    for start in range(0, n, chunk):
        block = data[:, start:start + chunk].astype(np.float64)
        centre = block.mean(axis=0)
        block -= centre
        mean[start:start + chunk] = centre
        data[:, start:start + chunk] = block
        gram += block @ block.T
    eigenvalues, vectors = np.linalg.eigh(gram)
    order = np.argsort(eigenvalues)[::-1]
    sv = np.sqrt(np.maximum(eigenvalues[order], 0.0))
    return GramPCA(mean=mean, left=vectors[:, order], singular_values=sv, gram=gram)


def scaled_components(centred: np.ndarray, left: np.ndarray, n_components: int,
                      chunk: int = _CHUNK) -> np.ndarray:
    """Q = VΣ = Xcᵀ·U for the first ``n_components`` columns of U, one row per component.

    Returns
    -------
    np.ndarray
        (K, n) float32.
    """
    n = centred.shape[1]
    u = left[:, :n_components].T  # (K, m)
    components = np.empty((n_components, n), np.float32)
    for start in range(0, n, chunk):
        components[:, start:start + chunk] = u @ centred[:, start:start + chunk].astype(np.float64)
    return components


def loo_residuals(gram: np.ndarray) -> np.ndarray:
    """Leave-one-out squared residual norms of the PCA, computed from the Gram matrix alone.

    For each material j the PCA is redone without it (mean and components of the other m − 1),
    and ``x_j − mean`` is projected onto the first K components; the squared norm of what is
    left is the error of the best reconstruction of an unseen material by K components. All
    inner products needed are entries of the Gram matrix, so this costs m small
    eigendecompositions and no pass over the data. (The mapping's median is not redone: it
    includes material j, a small optimism.)

    Parameters
    ----------
    gram : np.ndarray
        (m, m) Gram matrix of the data, centred by any common vector.

    Returns
    -------
    np.ndarray
        (m − 1,) mean over materials of the squared residual norm for K = 0, ..., m − 2 components
        (mapped units²; divide by the number of entries for a per-entry variance).
    """
    m = gram.shape[0]
    total = np.zeros(m - 1)
    for j in range(m):
        rest = np.delete(np.arange(m), j)
        g_rest = gram[np.ix_(rest, rest)]
        g_j = gram[rest, j]
        # r = x_j − μ with μ the mean of the others; a = X_rest·r, ‖r‖² from Gram entries.
        a = g_j - g_rest.mean(axis=1)
        norm2 = gram[j, j] - 2 * g_j.mean() + g_rest.mean()
        centring = np.eye(m - 1) - 1.0 / (m - 1)
        eigenvalues, vectors = np.linalg.eigh(centring @ g_rest @ centring)
        order = np.argsort(eigenvalues)[::-1][: m - 2]
        eigenvalues, vectors = eigenvalues[order], vectors[:, order]
        keep = eigenvalues > eigenvalues[0] * 1e-12
        # Coefficient of r on the unit component v_k = Ycᵀu_k/σ_k is u_kᵀ·C·a/σ_k.
        proj2 = np.where(keep, (vectors.T @ (centring @ a)) ** 2 / np.where(keep, eigenvalues, 1.0), 0.0)
        total += np.maximum(norm2 - np.concatenate([[0.0], np.cumsum(proj2)]), 0.0)
    return total / m


def build_basis(
    names: Sequence[str],
    load_table: Callable[[str], np.ndarray],
    n_components: int,
    epsilon: float = DEFAULT_EPSILON,
    on_table: Callable[[str], None] | None = None,
) -> BRDFBasis:
    """PCA basis of measured BRDF tables (Nielsen et al. 2015).

    Steps: per-entry median of the m tables (the mapping's reference), the log-relative mapping
    with clipped cosine weights (:func:`abs.brdf.basis.map_brdf`), centring, PCA by the Gram
    matrix, scaled eigenvectors Q = VΣ, and a leave-one-out estimate of the per-entry residual
    variance of an unseen material (for the regularisation of :mod:`abs.brdf.reconstruct`).

    Parameters
    ----------
    names : sequence of str
        Training materials (m >= 3).
    load_table : callable
        ``name -> (3, 90, 90, 180)`` BRDF table in 1/sr, e.g. :func:`abs.brdf.measured.measured_table`.
    n_components : int
        K, 1 <= K <= m − 1 (centred data of m tables has rank m − 1).
    epsilon : float
        ε of the mapping, 1/sr.
    on_table : callable, optional
        Called with each name after its table is loaded (progress reporting).

    Returns
    -------
    BRDFBasis
        With the optional training-set arrays filled in.
    """
    m = len(names)
    if m < 3:
        raise ValueError(f"need at least 3 training materials, got {m}")
    if not 1 <= n_components <= m - 1:
        raise ValueError(f"n_components must be in [1, {m - 1}] for {m} materials, got {n_components}")
    data = np.empty((m, MERL_SIZE), np.float32)
    for j, name in enumerate(names):
        table = np.asarray(load_table(name), dtype=np.float32).reshape(-1)
        if table.size != MERL_SIZE:
            raise ValueError(f"table of {name!r} has {table.size} values, expected {MERL_SIZE}")
        data[j] = table
        if on_table is not None:
            on_table(name)
    weight = merl_cosine_weight()
    median = np.empty(MERL_SIZE, np.float32)
    for start in range(0, MERL_SIZE, _CHUNK):
        cols = slice(start, start + _CHUNK)
        median[cols] = np.median(data[:, cols], axis=0)
        data[:, cols] = map_brdf(data[:, cols], median[cols], weight[cols], np.float32(epsilon))
    pca = gram_pca(data)
    components = scaled_components(data, pca.left, n_components)
    # A leave-one-out basis has at most m − 2 components: for K = m − 1 use that last value.
    residual = loo_residuals(pca.gram)[min(n_components, m - 2)]
    return BRDFBasis(
        mean=pca.mean,
        components=components,
        median=median,
        epsilon=epsilon,
        cosine_weight=weight,
        materials=np.asarray(list(names), dtype=str),
        training_coefficients=pca.left[:, :n_components],
        singular_values=pca.singular_values,
        residual_variance=residual / MERL_SIZE,
    )
