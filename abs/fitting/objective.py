"""A fit's objective over the unconstrained vector ``z``: what every optimiser minimises.

The optimisers (``optimisers/``) know nothing of renderers: they see residuals ``r(z)``, their
Jacobian and the gradient of ``|r|^2 / 2``. This module makes those from the forward model's pixel
residuals (:class:`~abs.model.problem.FitProblem`), so that every optimiser minimises the same
thing:

- pixel residuals divided by the pixel noise ``sigma`` (photograph and Monte-Carlo noise, linear
  RGB), which weighs them against the priors;
- one row ``(theta - mean) / sd`` per scalar with a Gaussian prior;
- derivatives taken through the bounded transform ``theta(z)`` (:class:`ParameterVector`).

Seeds are the optimisers' choice (common random numbers for Levenberg-Marquardt, fresh ones for
the refinement and Adam), so every method here takes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.fitting.settings import LM_MAX_SCALARS, FitSettings, schedule_value
from abs.model import FitProblem, ForwardModel, ParameterVector

__all__ = ["Objective"]


@dataclass
class Objective:
    """Weighted residuals of a model's training views, with the priors, as functions of ``z``.

    Attributes
    ----------
    model : ForwardModel
        The fitted model (its vector is the layout of ``z``).
    settings : FitSettings
        ``spp``, ``downsample``, ``clamp``, ``seed`` and Adam's schedules.
    sigma : float
        Pixel noise (linear RGB) that divides the pixel residuals.
    prior_mean, prior_sd : ndarray, shape (P,)
        Gaussian priors per scalar (physical units); ``sd = inf`` where there is none.
    """

    model: ForwardModel
    settings: FitSettings
    sigma: float
    prior_mean: np.ndarray
    prior_sd: np.ndarray

    @classmethod
    def build(cls, model: ForwardModel, settings: FitSettings, sigma: float,
              priors: dict) -> "Objective":
        """The objective with ``priors`` (name -> object with ``mean`` and ``sd``) laid out on
        the model's vector; parameters without a prior get none."""
        vector = model.vector
        mean, sd = np.full(vector.size, np.nan), np.full(vector.size, np.inf)
        for name, s in vector.slices().items():
            if name in priors:
                mean[s], sd[s] = priors[name].mean, priors[name].sd
        return cls(model, settings, sigma, mean, sd)

    @property
    def vector(self) -> ParameterVector:
        return self.model.vector

    @property
    def reweighted(self) -> bool:
        """Whether renders come from path-length recordings (every fitted parameter is an
        absorption, the environment's scale or a sensor parameter): then evaluating at a seed
        already used renders nothing (:attr:`abs.model.FitProblem.uses_recordings`)."""
        return self.problem().uses_recordings

    @property
    def free(self) -> np.ndarray:
        """Indices of the scalars whose new values render nothing at the other scalars' values
        (:attr:`abs.model.FitProblem.reweightable`) when some others do need renders (an IOR, a
        pose): Levenberg-Marquardt refits them between renders. Empty otherwise."""
        problem = self.problem()
        if problem.uses_recordings or not problem.reweightable:
            return np.zeros(0, int)
        slices = self.vector.slices()
        return np.concatenate([np.arange(slices[n].start, slices[n].stop)
                               for n in problem.reweightable])

    @property
    def has_prior(self) -> np.ndarray:
        """Which scalars have a prior (bool, shape (P,))."""
        return np.isfinite(self.prior_sd)

    def problem(self, factor: int | None = None) -> FitProblem:
        """The training views compared at ``1/factor`` resolution (default: the settings')."""
        s = self.settings
        return self.model.problem("train", s.downsample if factor is None else factor, s.clamp)

    def _with_priors(self, r: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """``r / sigma``, with the priors' rows ``(theta - mean) / sd`` below."""
        r = r / self.sigma
        if self.has_prior.any():
            return np.concatenate([r, ((theta - self.prior_mean) / self.prior_sd)[self.has_prior]])
        return r

    def _weighted_jacobian(self, J: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
        """``d(r / sigma) / dz``, with the priors' rows below."""
        J = J * dtheta / self.sigma
        has_prior = self.has_prior
        if has_prior.any():
            return np.concatenate([J, np.diag(dtheta / self.prior_sd)[has_prior]])
        return J

    def residuals(self, z: np.ndarray, seed: int, jacobian_seed: int | None = None,
                  factor: int | None = None, names=None, spp: int | None = None):
        """Weighted residuals at ``z`` and their Jacobian w.r.t. ``z``.

        Parameters
        ----------
        z : ndarray, shape (P,)
        seed : int
            Seed of the renders of ``r``.
        jacobian_seed : int, optional
            Seed of independent renders for ``J`` (default: the same renders as ``r``).
        factor : int, optional
            Compare at this downsampling factor instead of the settings' ``downsample`` (a
            coarse stage of Levenberg-Marquardt).
        names : sequence of str, optional
            Only these parameters' Jacobian columns (the others are zero).
        spp : int, optional
            Samples per pixel instead of the settings' ``spp`` (the refinement's).

        Returns
        -------
        r : ndarray, shape (n_residuals,)
        J : ndarray, shape (n_residuals, P)
        loss : float
            RMSE of the unweighted pixel residuals (linear RGB), the loss reported per iteration.
        """
        vector, s = self.vector, self.settings
        theta, dtheta = vector.to_physical(z), vector.derivative(z)
        r, J = self.problem(factor).residuals(theta, spp or s.spp, seed, jacobian=True,
                                              jacobian_seed=jacobian_seed, names=names)
        loss = float(np.sqrt(np.mean(r ** 2)))
        return self._with_priors(r, theta), self._weighted_jacobian(J, dtheta), loss

    def weighted_residuals(self, z: np.ndarray, seed: int, spp: int | None = None) -> np.ndarray:
        """The weighted residuals alone (no Jacobian: nothing rendered beyond the image) at
        ``z``, from renders seeded ``seed`` at ``spp`` samples per pixel (default: the
        settings'), with the priors' rows below."""
        theta = self.vector.to_physical(z)
        r = self.problem().residuals(theta, spp or self.settings.spp, seed)[0]
        return self._with_priors(r, theta)

    def jacobian(self, z: np.ndarray, seed: int, spp: int | None = None) -> np.ndarray:
        """The weighted Jacobian alone, from renders seeded ``seed`` (a second, independent
        Jacobian for the cross curvature), at ``spp`` samples per pixel (default: the
        settings')."""
        theta = self.vector.to_physical(z)
        J = self.problem().jacobian(theta, spp or self.settings.spp, seed)
        return self._weighted_jacobian(J, self.vector.derivative(z))

    def gradient(self, z: np.ndarray, iteration: int) -> tuple[float, np.ndarray]:
        """The RMSE and the gradient ``dL/dz`` of ``L = |r|^2 / 2`` at iteration ``iteration``.

        Renders follow Adam's schedules (``spp_schedule``, ``downsample_schedule``) and take a
        fresh seed per iteration, so successive gradients are independent and the steps
        unbiased. With few scalars the gradient is ``J^T r`` from forward-mode Jacobians; with
        many (more than ``LM_MAX_SCALARS``), one reverse-mode pass.
        """
        vector, s = self.vector, self.settings
        theta, dtheta = vector.to_physical(z), vector.derivative(z)
        problem = self.problem(schedule_value(s.downsample_schedule, iteration, s.downsample))
        spp = schedule_value(s.spp_schedule, iteration, s.spp)
        seed = s.seed + 1000 * (iteration + 1)
        if vector.size <= LM_MAX_SCALARS:
            r, J = problem.residuals(theta, spp, seed, jacobian=True, jacobian_seed=seed + 1)
            g = J.T @ r
        else:
            half, g = problem.gradient(theta, spp, seed, jacobian_seed=seed + 1)
            r = np.array([np.sqrt(2 * half)])
        has_prior = self.has_prior
        g = (g / self.sigma ** 2
             + np.where(has_prior, (theta - np.nan_to_num(self.prior_mean)) / self.prior_sd ** 2, 0.0))
        rms = float(np.sqrt(np.mean(r ** 2))) if r.size > 1 else float(r[0] / np.sqrt(problem.n_residuals))
        return rms, g * dtheta
