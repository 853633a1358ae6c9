"""Taming the chain's fixed-seed render noise with further seed pairs.

With fixed seeds the chain samples a posterior centred on the mode of one seed pair's
likelihood, which sits away from the noise-free mode by that pair's render noise. The likelihood
allows for the offset through ``var_render / 2`` per pixel (:mod:`abs.sampling.likelihood`),
which is right for Gaussian noise. Paths through glass give heavy-tailed noise: a few bright
samples move the mode further than per-pixel variances estimated from a handful of renders
predict, and one unlucky pair puts the whole posterior off (docs/sampling.md, "Measured
calibration"). So, at the mode ``theta``, ``K`` further seed pairs are rendered and used twice:

- **Recentring.** Their mean residual minus the chain pair's, times ``K / (K + 1)``, is added to
  the chain's residuals (``RenderPosterior.offset``): near the mode they then stand for the average
  of all ``K + 1`` pairs, so one unlucky chain pair no longer sets the posterior's centre. The
  offset is fixed (exact at the mode, first order around it), so the likelihood stays smooth and
  the crossed form's removal of the noise energy is untouched. The render variance is *not*
  divided by ``K + 1``: heavy-tailed estimates at one spp fall short of the mean alike (the rare
  bright paths are missing from all of them), a shortfall the pairs' scatter does not show; one
  pair's variance leaves room for it (measured in docs/sampling.md).
- **Calibration.** With ``J`` the Jacobian, ``W`` the weights and ``C = (J^T W J)^-1``, one
  Gauss-Newton step for pair ``k`` moves the mode by ``d_k = -C J^T W rbar_k``. The variance of
  ``d`` over the ``K + 1`` pairs is the render noise's share of a pair's mode scatter; the
  likelihood predicts ``diag(C J^T W diag(var_render / 2) W J C)``. The render variance is scaled
  by the largest ratio over the scalars, and never down (``K`` is small: the estimate is noisy,
  and a too-wide interval costs less than a too-narrow one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SeedPairCalibration", "calibrate_render_noise"]


@dataclass(frozen=True)
class SeedPairCalibration:
    """What :func:`calibrate_render_noise` found.

    Attributes
    ----------
    scale : float
        ``max(1, max_i ratio_i)``: the factor on the render variance.
    ratio : ndarray, shape (P,)
        Measured over modelled variance of a pair's mode offset, per scalar (NaN where the
        photographs do not constrain it).
    offset : ndarray, shape (M,)
        Residual offset recentring the chain's pair on the mean of all ``K + 1`` pairs.
    """

    scale: float
    ratio: np.ndarray
    offset: np.ndarray


def calibrate_render_noise(posterior, theta: np.ndarray, render_part: np.ndarray, pairs: int,
                           seed: int) -> SeedPairCalibration:
    """Render ``pairs`` further seed pairs at the mode; recentre and calibrate (module docstring).

    Parameters
    ----------
    posterior : RenderPosterior
        The chain's posterior, unscaled and without an offset.
    theta : ndarray, shape (P,)
        Its mode (:func:`abs.sampling.mode.find_mode`).
    render_part : ndarray, shape (M,)
        ``var_render / 2`` per residual (:meth:`NoiseModel.render_part`).
    pairs : int
        ``K >= 1`` further seed pairs (two renders of every training view each).
    seed : int
        First seed of the pairs (``seed .. seed + 2 K - 1``; keep them apart from the chain's).
    """
    problem = posterior.problem()
    weight = 1.0 / posterior.variance
    jac = 0.5 * sum(problem.jacobian(theta, posterior.spp, s) for s in posterior.seeds)
    # pinv: a direction the photographs do not constrain gets no gain (and no ratio) instead of
    # failing the run.
    gain = np.linalg.pinv(jac.T @ (weight[:, None] * jac)) @ (jac * weight[:, None]).T  # (P, M)
    own = 0.5 * sum(posterior.residuals(theta))
    others = [0.5 * (problem.residuals(theta, posterior.spp, seed + 2 * k)[0]
                     + problem.residuals(theta, posterior.spp, seed + 2 * k + 1)[0])
              for k in range(pairs)]
    offsets = np.array([-gain @ r for r in [own, *others]])
    measured = offsets.var(axis=0, ddof=1)
    modelled = np.einsum("pm,m,pm->p", gain, render_part, gain)
    ratio = np.where(modelled > 0, measured / np.where(modelled > 0, modelled, 1.0), np.nan)
    shift = pairs / (pairs + 1) * (np.mean(others, axis=0) - own)
    finite = ratio[np.isfinite(ratio)]
    return SeedPairCalibration(max(1.0, float(finite.max())) if finite.size else 1.0, ratio, shift)
