"""abs's data-driven model per surface point: ``brdf_pca`` coefficients (docs/brdf.md).

Each measurement ``f_r cos(theta_l)``, divided by ``cos(theta_l)``, is one observed BRDF value per
channel at the MERL table entry nearest its (normalised) light and view directions
(:func:`abs.brdf.directions.merl_entries`); a point's coefficients are the regularised least
squares of :func:`abs.brdf.reconstruct.fit_coefficients` over its entries (Nielsen et al. 2015:
linear in the basis' log-relative mapped space, with the prior's ``eta`` from the basis' own
held-out residual and the measurements' relative noise). The coefficients are shared by the three
channels: the basis holds colour, as the ``brdf_pca`` scene material does.

Rendering a point evaluates only the entries a pixel needs, ``unmap(mean[e] + c . Q[:, e])``, never
the full 4.4-million-entry table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.brdf.basis import BRDFBasis, unmap_brdf
from abs.brdf.directions import merl_entries
from abs.brdf.reconstruct import fit_coefficients
from abs.lightstage.measure import Measurements, PoseView
from abs.lightstage.normalise import normalise
from abs.lightstage.surface import SurfacePoints

__all__ = ["PcaFits", "fit_pca_points", "pca_reflectance", "MIN_COS_L"]

MIN_COS_L = 0.2
"""Measurements with ``cos(theta_l)`` below this are not used: dividing by the cosine to get
``f_r`` would amplify their noise and normal error five-fold or more."""


@dataclass(frozen=True)
class PcaFits:
    """Per-point ``brdf_pca`` coefficients.

    Attributes
    ----------
    coefficients : np.ndarray
        (P, K) coefficients; zeros (the basis' mean material) where not fitted.
    count : np.ndarray
        (P,) measurements each point was fitted to (0: not fitted).
    """

    coefficients: np.ndarray
    count: np.ndarray


def fit_pca_points(basis: BRDFBasis, meas: Measurements, n_points: int, min_measurements: int = 8,
                   noise: float = 0.05, eta: float | None = None) -> PcaFits:
    """Fit coefficients per surface point to the fitting (not held-out) measurements.

    Parameters
    ----------
    basis : BRDFBasis
        The PCA basis.
    meas : Measurements
        Light-stage measurements (:mod:`~abs.lightstage.measure`).
    n_points : int
        Number of surface points.
    min_measurements : int
        Points with fewer usable measurements are not fitted.
    noise : float
        Relative noise of the observed BRDF values, for the prior's weight ``eta``.
    eta : float, optional
        The prior's weight; from the basis' training statistics and ``noise`` when omitted
        (:func:`abs.brdf.reconstruct.default_eta`).
    """
    train = meas.select(~meas.held_out)
    iso = normalise(train.normal.astype(np.float64), train.light.astype(np.float64),
                    train.view.astype(np.float64))
    use = (iso.cos_l > MIN_COS_L) & (iso.cos_v > 0.0)
    entries = merl_entries(iso.light[use], iso.view[use])  # (M, 3)
    f = train.value[use].astype(np.float64) / iso.cos_l[use, None]
    point = train.point[use]
    coefficients = np.zeros((n_points, basis.n_components))
    count = np.zeros(n_points, np.int64)
    order = np.argsort(point, kind="stable")
    bounds = np.searchsorted(point[order], np.arange(n_points + 1))
    for p in range(n_points):
        idx = order[bounds[p]:bounds[p + 1]]
        if len(idx) < min_measurements:
            continue
        coefficients[p] = fit_coefficients(basis, entries[idx], f[idx], eta=eta, noise=noise)
        count[p] = len(idx)
    return PcaFits(coefficients, count)


def pca_reflectance(basis: BRDFBasis, fits: PcaFits, points: SurfacePoints):
    """The per-point fit as a :data:`~abs.lightstage.render.Reflectance` (``f_r cos(theta_l)``).

    Points not fitted take the nearest fitted point's coefficients (as
    :func:`~abs.lightstage.render.fitted_reflectance` does).
    """
    from scipy.spatial import cKDTree

    coef = fits.coefficients
    fitted = np.nonzero(fits.count > 0)[0]
    if 0 < len(fitted) < len(coef):
        _, nearest = cKDTree(points.position[fitted]).query(points.position)
        coef = coef[fitted[nearest]]
    mean, comps = basis.mean, basis.components
    median, weight = basis.median, basis.cosine_weight

    def reflectance(view: PoseView, wi: np.ndarray) -> np.ndarray:
        pid = points.lookup(view.hits.triangle, view.hits.barycentric)
        iso = normalise(view.hits.normal, wi, view.view)
        e = merl_entries(iso.light, iso.view)  # (N, 3)
        x = mean[e].astype(np.float64) + np.einsum("nk,knc->nc", coef[pid], comps[:, e].astype(np.float64))
        f = np.clip(unmap_brdf(x, median[e].astype(np.float64), weight[e].astype(np.float64), basis.epsilon), 0, None)
        return f * np.clip(iso.cos_l, 0.0, None)[:, None]

    return reflectance
