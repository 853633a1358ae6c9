"""Taming the chain's fixed-seed render noise with further seed pairs.

With fixed seeds the chain samples a posterior centred on the mode of one seed pair's
likelihood, which sits away from the noise-free mode by that pair's render noise. Paths through
glass give heavy-tailed noise: a few bright samples move the mode further than per-pixel
variances estimated from a handful of renders predict, and one unlucky pair puts the whole
posterior off (docs/sampling.md, "Measured calibration"). So, at the mode ``theta``, ``K``
further seed pairs are rendered and used twice:

- **Recentring.** Each of the chain's two renders gets its own fixed offset: ``o_a = c (rbar_others
  - r_a)`` and ``o_b = c (rbar_others - r_b)`` at the mode, ``c = K / (K + 1)``,
  ``rbar_others`` the mean residual of the further pairs (``RenderPosterior.offset``). At the mode
  the chain's residual average is then that of all ``K + 1`` pairs, and around it the offsets are
  first order. Why one offset per render: an offset shared by both renders, ``c (rbar_others -
  (r_a + r_b) / 2)``, holds ``r_a``'s noise and so multiplies render ``a``'s own residual in the
  crossed product; where the noise depends on the parameters (it does: clearer glass or a brighter
  environment is noisier) that product's expectation depends on them too, which is the
  noise-energy bias the crossed form exists to remove (measured: absorption posteriors half a
  posterior sd low over 10 SBC datasets; tests/test_sampling.py shows it on a stand-in). With
  ``o_b`` free of render ``a``'s noise and ``o_a`` of ``b``'s, every product pairs independent
  noises and the bias is gone. The offsets are fixed, so the likelihood stays smooth.
- **Calibration.** With ``J`` the Jacobian, ``W`` the weights and ``C = (J^T W J)^-1``, one
  Gauss-Newton step for pair ``k`` moves the mode by ``d_k = -C J^T W rbar_k``. ``J`` comes from
  two more renders, independent of every pair: a Jacobian from the chain pair's own renders
  correlates with their noise (a bright path raises a pixel and its derivative alike) and would
  set that pair's ``d`` apart from the others'. The variance of ``d`` over the ``K + 1`` pairs is
  the render noise's share of a pair's mode scatter; the likelihood predicts
  ``diag(C J^T W diag(var_render / 2) W J C)``. The render variance is scaled by the largest ratio
  over the scalars, and never down (``K`` is small: the estimate is noisy, and a too-wide interval
  costs less than a too-narrow one). After recentring, the chain's residuals stand for the
  average of ``K + 1`` pairs, so the likelihood's render variance is ``scale var_render / (2 (K +
  1))`` (``NoiseModel.render_pairs``).
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
    offset : ndarray, shape (2, M)
        Residual offsets of the chain's two renders, recentring them on the mean of all
        ``K + 1`` pairs.
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
        First seed of the pairs (``seed .. seed + 2 K - 1``, then two for the Jacobian; keep them
        apart from the chain's).
    """
    problem = posterior.problem()
    weight = 1.0 / posterior.variance
    jac = 0.5 * sum(problem.jacobian(theta, posterior.spp, seed + 2 * pairs + i) for i in range(2))
    # pinv: a direction the photographs do not constrain gets no gain (and no ratio) instead of
    # failing the run.
    gain = np.linalg.pinv(jac.T @ (weight[:, None] * jac)) @ (jac * weight[:, None]).T  # (P, M)
    r_a, r_b = posterior.residuals(theta)
    own = 0.5 * (r_a + r_b)
    others = [0.5 * (problem.residuals(theta, posterior.spp, seed + 2 * k)[0]
                     + problem.residuals(theta, posterior.spp, seed + 2 * k + 1)[0])
              for k in range(pairs)]
    offsets = np.array([-gain @ r for r in [own, *others]])
    measured = offsets.var(axis=0, ddof=1)
    modelled = np.einsum("pm,m,pm->p", gain, render_part, gain)
    ratio = np.where(modelled > 0, measured / np.where(modelled > 0, modelled, 1.0), np.nan)
    c, mean_others = pairs / (pairs + 1), np.mean(others, axis=0)
    shift = np.stack([c * (mean_others - r_a), c * (mean_others - r_b)])
    finite = ratio[np.isfinite(ratio)]
    return SeedPairCalibration(max(1.0, float(finite.max())) if finite.size else 1.0, ratio, shift)
