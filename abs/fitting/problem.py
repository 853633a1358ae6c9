"""The fitting problem: residuals between renderings and photographs, and their derivatives.

:class:`FitProblem` owns a compiled scene, the compared views and the parameter layout. Its
residual vector stacks, over the training views, ``clamp(rendering) - photograph`` on every masked
pixel and channel (linear RGB). Derivatives come from Dr.Jit, never from finite differences:

- :meth:`FitProblem.residuals` with ``jacobian=True`` pushes one tangent per parameter scalar
  through an attached render (forward mode). With few scalars (the usual case: absorption, IOR,
  scale, pose) this costs one render per scalar and gives the whole Jacobian that Gauss-Newton,
  Levenberg-Marquardt and the Laplace approximation need.
- :meth:`FitProblem.gradient` gives the same ``J^T r`` by one reverse pass (plus one primal
  render for ``r``), for problems with many scalars (textures, BRDF coefficients), used by Adam.

Renders use a seed per call, so the same ``(theta, seed)`` gives the same image (common random
numbers): the optimiser then sees a deterministic objective.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.fitting.observations import Observation
from abs.fitting.parameters import ParameterVector
from abs.render.compiled import CompiledScene
from abs.render.jit import from_numpy

__all__ = ["FitProblem", "AD_SAMPLES_PER_BATCH"]

# Camera samples recorded per AD pass: the recorded graph grows with it (about 1-2 kB per path on
# the CPU backend at depth 12), so large AD renders are split into spp batches.
AD_SAMPLES_PER_BATCH = 1 << 18


def _view_seed(seed: int, view: int) -> int:
    """The render seed of view number ``view`` for a call seeded ``seed`` (spp batches add 0, 1,
    ...): distinct per view, and the same in every method, so residuals, Jacobians and gradients
    seeded alike see the same samples."""
    return seed * 1009 + view * 101


@dataclass
class RenderCounter:
    """How much rendering a fit used."""

    renders: int = 0
    samples: int = 0

    def add(self, camera, spp: int) -> None:
        self.renders += 1
        self.samples += camera.width * camera.height * spp


@dataclass
class FitProblem:
    """Renderings of ``compiled`` against ``observations`` as functions of ``vector``'s parameters.

    Parameters
    ----------
    compiled : CompiledScene
    vector : ParameterVector
        The fitted parameters.
    observations : list of Observation
        Training views (holdout views are evaluated by the caller, never fitted).
    clamp : float or None
        Renderings are clamped to ``[.., clamp]`` before comparison (photographs that saturate at
        ``clamp``, e.g. 1.0 for low-dynamic-range images); clamped pixels carry no gradient.
    max_depth : int or None
        Path length (default: the scene's).
    """

    compiled: CompiledScene
    vector: ParameterVector
    observations: list[Observation]
    clamp: float | None = None
    max_depth: int | None = None
    counter: RenderCounter = field(default_factory=RenderCounter)

    @property
    def n_residuals(self) -> int:
        return 3 * sum(o.pixels for o in self.observations)

    # ------------------------------------------------------------- values
    def set_values(self, theta: np.ndarray) -> None:
        """Write physical values (detached) into the compiled scene."""
        for name, value in self.vector.split(theta).items():
            self.compiled.set(name, value)

    def _attach(self, theta: np.ndarray) -> mi.Float:
        """Write ``theta`` as one attached Dr.Jit array; returns it."""
        attached = from_numpy(mi.Float, theta)
        dr.enable_grad(attached)
        for name, s in self.vector.slices().items():
            index = dr.arange(mi.UInt32, s.stop - s.start) + s.start
            self.compiled.set(name, dr.gather(mi.Float, attached, index))
        return attached

    def _batches(self, camera, spp: int) -> list[int]:
        per = max(1, min(spp, AD_SAMPLES_PER_BATCH // (camera.width * camera.height)))
        return [per] * (spp // per) + ([spp % per] if spp % per else [])

    def render(self, observation: Observation, theta: np.ndarray, spp: int, seed: int) -> np.ndarray:
        """Primal rendering (H, W, 3) of one observation at ``theta``."""
        self.set_values(theta)
        with dr.suspend_grad():
            image = self.compiled.render(observation.camera, spp=spp, seed=seed,
                                         max_depth=self.max_depth).numpy()
        self.counter.add(observation.camera, spp)
        return image.astype(np.float64)

    # ---------------------------------------------------------- residuals
    def _clamp(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The image as compared, and where it carries derivatives (not clamped)."""
        if self.clamp is None:
            return image, np.ones_like(image, bool)
        return np.minimum(image, self.clamp), image < self.clamp

    def _compare(self, observation: Observation, image: np.ndarray):
        """Residuals of one view and the mask of residuals that carry derivatives."""
        clamped, live = self._clamp(image)
        m = observation.mask
        return (clamped - observation.photograph)[m].ravel(), live[m].ravel()

    def residuals(self, theta: np.ndarray, spp: int, seed: int, jacobian: bool = False,
                  jacobian_seed: int | None = None):
        """Residual vector at physical ``theta`` and, optionally, its Jacobian.

        With ``jacobian_seed`` (different from ``seed``) the Jacobian comes from an independent
        render. Residuals and Jacobian from the same render are correlated through the Monte-Carlo
        noise, which biases ``J^T r`` (the gradient) towards darker, less noisy renderings;
        independent renders make ``J^T r`` unbiased.

        Returns
        -------
        r : ndarray, shape (M,)
        J : ndarray, shape (M, P) or None
            ``d r / d theta`` (physical units), by forward-mode AD through the renderer.
        """
        rs, js = [], []
        for k, obs in enumerate(self.observations):
            view_seed = _view_seed(seed, k)
            if not jacobian:
                r, _ = self._compare(obs, self.render(obs, theta, spp, view_seed))
                rs.append(r)
                continue
            image, jac = self._render_with_jacobian(
                obs, theta, spp, view_seed if jacobian_seed is None else _view_seed(jacobian_seed, k))
            if jacobian_seed is not None and jacobian_seed != seed:
                image = self.render(obs, theta, spp, view_seed)
            r, live = self._compare(obs, image)
            rs.append(r)
            js.append(jac[obs.mask].reshape(-1, self.vector.size) * live[:, None])
        return np.concatenate(rs), (np.concatenate(js) if jacobian else None)

    def jacobian(self, theta: np.ndarray, spp: int, seed: int) -> np.ndarray:
        """The Jacobian (M, P) alone, from renders seeded ``seed`` (as :meth:`residuals` would
        seed them); the clamp mask comes from the same renders.

        Two Jacobians from different seeds give an unbiased estimate of ``J^T J`` as
        ``(J1^T J2 + J2^T J1) / 2``: the product of one noisy Jacobian with itself is inflated by
        the Jacobian's Monte-Carlo variance (measured: 3x at 16 spp for an IOR), which shortens
        Gauss-Newton steps and understates standard errors.
        """
        js = []
        for k, obs in enumerate(self.observations):
            image, jac = self._render_with_jacobian(obs, theta, spp, _view_seed(seed, k))
            live = self._clamp(image)[1][obs.mask].ravel()
            js.append(jac[obs.mask].reshape(-1, self.vector.size) * live[:, None])
        return np.concatenate(js)

    def _render_with_jacobian(self, obs: Observation, theta, spp: int, seed: int):
        cam, p = obs.camera, self.vector.size
        image = np.zeros((cam.height, cam.width, 3))
        jac = np.zeros((cam.height, cam.width, 3, p))
        for b, n in enumerate(self._batches(cam, spp)):
            for i in range(p):
                # One attached render per tangent (the same seed, so the same samples): a
                # recorded graph cannot be traversed twice when parameters are read inside the
                # BSDFs' virtual calls (Dr.Jit refuses to re-enter their isolated scopes).
                attached = self._attach(theta)
                rendered = self.compiled.render(cam, spp=n, seed=seed + b, max_depth=self.max_depth)
                self.counter.add(cam, n)
                if i == 0:
                    image += rendered.numpy() * (n / spp)
                tangent = np.zeros(p, np.float32)
                tangent[i] = 1.0
                dr.set_grad(attached, from_numpy(mi.Float, tangent))
                dr.forward_to(rendered)
                jac[..., i] += dr.grad(rendered).numpy() * (n / spp)
                del rendered, attached
        self.set_values(theta)  # drop the graph
        return image, jac

    def gradient(self, theta: np.ndarray, spp: int, seed: int,
                 jacobian_seed: int) -> tuple[float, np.ndarray]:
        """Half the sum of squared residuals and its gradient ``J^T r`` w.r.t. ``theta``, by one
        reverse pass per view and spp batch.

        ``r`` comes from the render seeded ``seed`` and ``J`` from the independent renders seeded
        ``jacobian_seed``, as in :meth:`residuals` (so ``J^T r`` is unbiased); the result equals
        ``J.T @ r`` of ``residuals(theta, spp, seed, True, jacobian_seed)``.
        """
        total, grad = 0.0, np.zeros(self.vector.size)
        for k, obs in enumerate(self.observations):
            cam = obs.camera
            image = self.render(obs, theta, spp, _view_seed(seed, k))
            r, _ = self._compare(obs, image)
            total += 0.5 * float(r @ r)
            clamped, live = self._clamp(image)
            residual = (clamped - obs.photograph) * (obs.mask[..., None] & live)
            weight = from_numpy(mi.Float, residual)
            for b, n in enumerate(self._batches(cam, spp)):
                attached = self._attach(theta)
                rendered = self.compiled.render(cam, spp=n, seed=_view_seed(jacobian_seed, k) + b,
                                                max_depth=self.max_depth)
                self.counter.add(cam, n)
                dr.backward(dr.sum(rendered.array * weight) * (n / spp))
                grad += dr.grad(attached).numpy()
                del rendered, attached
        self.set_values(theta)
        return total, grad
