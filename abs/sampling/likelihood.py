"""The likelihood of the photographs given rendered parameters, and its noise model.

Model. A photograph is ``y = f(theta*) + e_photo`` and a rendering with seed ``s`` is
``f(theta) + e_s(theta)``, ``f`` the noise-free image, ``e_photo`` sensor noise and ``e_s`` the
Monte-Carlo noise of the render. Every evaluation uses the same seeds (common random numbers), so
``e_s(theta)`` is a smooth function of ``theta`` and the log-likelihood is smooth too; but a
fixed-seed render's noise is then a fixed offset shared by all evaluations, not something that
averages away along the chain. Marginalised over that offset, the residual ``r_s = f(theta) +
e_s - y`` is Gaussian with variance ``var_photo + var_render`` per pixel and channel, which is why
the render's variance must be in the likelihood: without it the posterior is too narrow and
centred on one noisy render's optimum.

Two fixed seeds ``a`` and ``b`` are rendered per evaluation and the log-likelihood is

    log L(theta) = -1/2 sum_i r_a,i r_b,i / (var_photo,i + var_render,i / 2)

(the "crossed" form). Its Gaussian kernel is that of the averaged render ``(r_a + r_b)/2`` minus
``|r_a - r_b|^2 / 4``: it drops the render-noise energy ``|e(theta)|^2``, which grows with the
rendering's brightness and so would pull a plain least-squares likelihood towards darker, less
noisy renderings (the errors-in-variables bias described in docs/fitting.md, several posterior
standard deviations at low spp). For the linear case ``f = A theta`` its maximum is
``(A^T A)^-1 A^T (y - (e_a + e_b)/2)`` and its curvature ``A^T A / var``, so its intervals are
calibrated (tests/test_sampling.py checks both forms against the closed form).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["NoiseModel", "gaussian_log_likelihood", "crossed_log_likelihood",
           "render_variance", "smooth_variance"]


def gaussian_log_likelihood(residuals: np.ndarray, variance: np.ndarray | float) -> float:
    """``-1/2 sum r^2 / var`` (constants dropped: the variance does not depend on theta)."""
    r = np.asarray(residuals, np.float64)
    return -0.5 * float(np.sum(r * r / variance))


def crossed_log_likelihood(residuals_a: np.ndarray, residuals_b: np.ndarray,
                           variance: np.ndarray | float) -> float:
    """``-1/2 sum r_a r_b / var`` from the residuals of two independent fixed-seed renders
    (``variance`` is that of their average: ``var_photo + var_render / 2``)."""
    return -0.5 * float(np.sum(np.asarray(residuals_a) * np.asarray(residuals_b) / variance))


def smooth_variance(variance: np.ndarray, radius: int = 1) -> np.ndarray:
    """Box-average a per-pixel variance map (H, W, C) over ``(2 radius + 1)^2`` pixels.

    A variance from two renders has one degree of freedom per pixel (it is often near zero); a
    neighbourhood average makes it a usable weight while keeping its spatial structure (glass is
    far noisier than a diffuse floor)."""
    v = np.asarray(variance, np.float64)
    h, w = v.shape[:2]
    padded = np.pad(v, ((radius, radius), (radius, radius)) + ((0, 0),) * (v.ndim - 2), mode="edge")
    out = np.zeros_like(v)
    for dy in range(2 * radius + 1):
        for dx in range(2 * radius + 1):
            out += padded[dy:dy + h, dx:dx + w]
    return out / (2 * radius + 1) ** 2


def render_variance(renders: np.ndarray) -> np.ndarray:
    """Per-pixel Monte-Carlo variance of one render from ``n >= 2`` independent renders at the
    same spp, shape (n, H, W, 3): their sample variance, smoothed by :func:`smooth_variance`.

    Monte-Carlo noise through glass is heavy-tailed (rare bright paths); more renders catch
    more of its variance, two renders alone tend to miss it."""
    return smooth_variance(np.var(np.asarray(renders, np.float64), axis=0, ddof=1))


@dataclass(frozen=True)
class NoiseModel:
    """Per-view noise of the compared images (linear RGB, radiance units squared).

    Attributes
    ----------
    photo_variance : ndarray, shape (V,)
        Variance of each view's photograph about the noise-free rendering (sensor noise and
        model error), assumed white.
    render_variance : list of ndarray, each (H, W, 3)
        Monte-Carlo variance of one render at the sampling spp, per pixel and channel.
    immerkaer_sd : ndarray, shape (V,), optional
        Immerkaer's white-noise estimate of each photograph, for comparison only (image
        structure at low resolution inflates it).
    render_scale : float
        Factor on ``render_variance`` in the likelihood (>= 1): set so that the scatter of the
        posterior mode over independent seed pairs is what the likelihood allows for
        (:mod:`abs.sampling.calibration`; heavy-tailed Monte-Carlo noise through glass moves the
        mode further than its per-pixel variance predicts).
    render_pairs : int
        Independent seed pairs the likelihood's residuals average (1, or ``K + 1`` once
        recentred on ``K`` further pairs by :mod:`abs.sampling.calibration`).
    correlation : ndarray, shape (V, 3), optional
        Per view and channel, the factor by which the pixels' noise correlation shrinks the
        information they carry (1: independent pixels). A capture built from raw photographs
        spreads each sensor site's noise over neighbouring pixels (demosaicing), and a likelihood
        that treats its pixels as independent is too narrow; its variances are multiplied by the
        mean row sum of the noise's correlation matrix ``K`` (for a smooth signal ``J^T K J``
        is that many times ``J^T J``: a magnitude adjustment of the composite likelihood,
        :meth:`abs.render.footprint.FootprintFilm.correlate`).
    """

    photo_variance: np.ndarray
    render_variance: list[np.ndarray]
    immerkaer_sd: np.ndarray | None = None
    render_scale: float = 1.0
    render_pairs: int = 1
    correlation: np.ndarray | None = None

    def residual_variance(self, masks: list[np.ndarray]) -> np.ndarray:
        """Variance of each residual (the order of ``FitProblem.residuals``) of the likelihood's
        rendering: the average of ``render_pairs`` pairs of independent renders (times the
        views' :attr:`correlation` factors)."""
        share = self.render_scale / (2 * self.render_pairs)
        factors = (np.ones((len(masks), 3)) if self.correlation is None
                   else np.asarray(self.correlation, np.float64))
        parts = [((p + share * v) * f)[m].ravel()
                 for p, v, m, f in zip(self.photo_variance, self.render_variance, masks, factors)]
        return np.concatenate(parts)

    def render_part(self, masks: list[np.ndarray]) -> np.ndarray:
        """``var_render / 2`` per residual: the render noise of one seed pair's average."""
        return np.concatenate([(v / 2)[m].ravel() for v, m in zip(self.render_variance, masks)])

    def to_dict(self) -> dict:
        out = {"photo_sd": np.sqrt(self.photo_variance).tolist(),
               "render_sd_median": [float(np.sqrt(np.median(v))) for v in self.render_variance],
               "render_scale": float(self.render_scale), "render_pairs": int(self.render_pairs)}
        if self.immerkaer_sd is not None:
            out["photo_sd_immerkaer"] = np.asarray(self.immerkaer_sd).tolist()
        if self.correlation is not None:
            out["noise_correlation"] = np.asarray(self.correlation).tolist()
        return out
