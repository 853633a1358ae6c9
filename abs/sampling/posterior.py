"""Log-posterior densities over physical parameter values, for any residual function.

The sampler only needs ``log_prob(theta)``; two implementations:

- :class:`ResidualPosterior`: any residual function (a linear stand-in in the tests, or a
  user's model) with a known residual variance.
- :class:`RenderPosterior`: residuals of renderings against a capture's training views, the same
  parameters, bounds and priors as ``abs fit``. It is a picklable description, not a live scene:
  every process (or thread) that evaluates it compiles its own scene on first use, because Dr.Jit
  state (compiled kernels, the scene, AD graphs) belongs to one process and thread. The same
  object therefore runs in-process, in a local process pool or on Dask workers.

Both work in physical units with a flat prior inside the bounds (``-inf`` outside) plus the scene
file's Gaussian priors.
"""

from __future__ import annotations

import threading
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from abs.sampling.likelihood import crossed_log_likelihood, gaussian_log_likelihood

__all__ = ["LogPrior", "ResidualPosterior", "RenderPosterior"]


@dataclass(frozen=True)
class LogPrior:
    """Bounds (flat inside, ``-inf`` outside) and independent Gaussian priors per scalar.

    Attributes
    ----------
    lower, upper : ndarray, shape (P,)
        Physical bounds (may be infinite). The open interval is allowed.
    mean, sd : ndarray, shape (P,)
        Gaussian prior per scalar; ``sd = inf`` means none.
    """

    lower: np.ndarray
    upper: np.ndarray
    mean: np.ndarray | None = None
    sd: np.ndarray | None = None

    @classmethod
    def from_vector(cls, vector, priors: dict) -> "LogPrior":
        """Bounds of a :class:`~abs.model.parameters.ParameterVector` and the scene's
        ``[fit.priors]`` (``Scene.fit_priors``: name -> object with ``mean`` and ``sd``)."""
        mean, sd = np.zeros(vector.size), np.full(vector.size, np.inf)
        for name, s in vector.slices().items():
            if name in priors:
                mean[s], sd[s] = priors[name].mean, priors[name].sd
        return cls(vector.lower.copy(), vector.upper.copy(), mean, sd)

    def __call__(self, theta: np.ndarray) -> float:
        theta = np.asarray(theta, np.float64)
        if not np.all((theta > self.lower) & (theta < self.upper)):
            return -np.inf
        if self.sd is None:
            return 0.0
        has = np.isfinite(self.sd)
        return -0.5 * float(np.sum(np.square((theta[has] - self.mean[has]) / self.sd[has])))


@dataclass(frozen=True)
class ResidualPosterior:
    """``log p(theta) = log prior + log L`` for a residual function with known variance.

    Attributes
    ----------
    residuals : callable
        ``theta -> [r]`` (Gaussian likelihood) or ``theta -> [r_a, r_b]`` (two independent
        fixed-seed evaluations: the crossed likelihood of :mod:`abs.sampling.likelihood`).
    variance : float or ndarray, shape (M,)
        Variance of each residual (of their average for the crossed form).
    prior : LogPrior
    """

    residuals: Callable[[np.ndarray], Sequence[np.ndarray]]
    variance: np.ndarray | float
    prior: LogPrior

    def __call__(self, theta: np.ndarray) -> float:
        lp = self.prior(theta)
        if not np.isfinite(lp):
            return -np.inf
        rs = self.residuals(np.asarray(theta, np.float64))
        ll = (gaussian_log_likelihood(rs[0], self.variance) if len(rs) == 1
              else crossed_log_likelihood(rs[0], rs[1], self.variance))
        return lp + ll


# Problems compiled by this thread, by posterior token (Dr.Jit state is per process and thread).
_LOCAL = threading.local()


@dataclass(frozen=True)
class RenderPosterior:
    """The posterior of scene parameters given a capture's training views (picklable).

    Attributes
    ----------
    scene : Scene or path
    capture : path
        Capture folder.
    names : tuple of str
        Sampled parameters, in order (their scalars make ``theta``).
    spp : int
        Samples per pixel of each likelihood render.
    downsample : int
        Images compared box-averaged by this factor.
    seeds : (int, int)
        The two fixed seeds (common random numbers) of every evaluation.
    variance : ndarray, shape (M,)
        Residual variance of the averaged render (``NoiseModel.residual_variance``).
    prior : LogPrior
    clamp : float or None
    variant : str or None
        Mitsuba variant for worker processes.
    offset : ndarray, shape (2, M), optional
        One fixed offset per render, added to its residuals: the mean residual of further seed
        pairs minus that render's, at the mode, times ``K / (K + 1)``
        (:mod:`abs.sampling.calibration`), so that the residuals stand for the average of all
        ``K + 1`` pairs near the mode.
    reweight : bool
        Evaluate from path-length recordings where the parameters allow (the two seeds'
        recordings are made once and reweighted at every ``theta``).
    """

    scene: object
    capture: str
    names: tuple[str, ...]
    spp: int
    downsample: int
    seeds: tuple[int, int]
    variance: np.ndarray
    prior: LogPrior
    clamp: float | None = None
    variant: str | None = None
    offset: np.ndarray | None = None
    reweight: bool = True
    token: str = field(default_factory=lambda: uuid.uuid4().hex)

    def problem(self):
        """This thread's :class:`~abs.model.problem.FitProblem` (compiled on first use)."""
        cache = getattr(_LOCAL, "problems", {})
        if self.token not in cache:
            if self.variant:
                from abs.render.variant import set_variant

                set_variant(self.variant)
            from abs.model import build_model

            scene = Path(self.scene) if isinstance(self.scene, str) else self.scene
            model = build_model(scene, self.capture, self.names, reweight=self.reweight)
            self.adopt(model.problem("train", self.downsample, self.clamp))
        return _LOCAL.problems[self.token]

    def adopt(self, problem) -> None:
        """Use an already compiled problem in this thread (saves compiling the scene twice)."""
        cache = getattr(_LOCAL, "problems", None)
        if cache is None:
            cache = _LOCAL.problems = {}
        cache[self.token] = problem

    def residuals(self, theta: np.ndarray) -> list[np.ndarray]:
        """Residuals of the two fixed-seed renders at physical ``theta`` (plus ``offset``)."""
        problem = self.problem()
        shifts = (0.0, 0.0) if self.offset is None else self.offset
        return [problem.residuals(theta, self.spp, seed)[0] + shift
                for seed, shift in zip(self.seeds, shifts)]

    def __call__(self, theta: np.ndarray) -> float:
        return ResidualPosterior(self.residuals, self.variance, self.prior)(theta)
