"""The forward problem: residuals between renderings and photographs, and their derivatives.

Fitting, sampling and diagnosis all ask the same questions of a scene and a capture: what are the
residuals at these parameter values, and how do they change. They ask them through one class, so
that seeds, clamping, the residual order and render accounting agree between a fit and the
posterior or the diagnosis built on it.

:class:`FitProblem` owns a compiled scene, the compared views and the parameter layout. Its
residual vector stacks, over the training views, ``clamp(rendering) - photograph`` on every masked
pixel and channel (linear RGB), times the pixel's weight when the capture gives the photographs'
noise (:func:`abs.model.observations.pixel_weights`: the noisier the pixel, the smaller; 1 for a
typical pixel, and for every pixel without noise images). Derivatives come from Dr.Jit, never
from finite differences:

- :meth:`FitProblem.residuals` with ``jacobian=True`` renders forward-mode derivatives
  (:meth:`CompiledScene.render_forward`: tangents carried inside the path loop, about 1.6 primal
  renders each, memory independent of samples and path length): one per scalar, or one per
  per-channel parameter whose channels are separable (absorption, IOR, reflectance colour; see
  :meth:`FitProblem.column_passes`). With few scalars (the usual case: absorption, IOR, scale,
  pose) this gives the whole Jacobian that Gauss-Newton, Levenberg-Marquardt and the Laplace
  approximation need.
- :meth:`FitProblem.gradient` gives the same ``J^T r`` by one reverse pass (plus one primal
  render for ``r``), for problems with many scalars (textures, BRDF coefficients), used by Adam.

Renders use a seed per call, so the same ``(theta, seed)`` gives the same image (common random
numbers): the optimiser then sees a deterministic objective.

When every varying parameter reweights from a path-length recording (a glass absorption, the
environment scale, the sensor: :attr:`FitProblem.uses_recordings`), each ``(view, spp, seed)`` is
rendered once, as a recording (:mod:`abs.render.path_lengths`), and every render and Jacobian at
that seed reweights it: the same samples as the render it stands for, so nothing above changes
but the cost. When only some do (:attr:`FitProblem.reweightable`, beside an IOR or a pose), each
render is a recording at the other parameters' values, and the reweightable parameters' Jacobian
columns and any value of them at those values come from it without rendering: what lets a fit
refit them between renders (:func:`abs.fitting.optimisers.lm.levenberg_marquardt`'s ``refit``).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from abs.model.counter import RenderCounter
from abs.model.observations import Observation, pixel_weights
from abs.model.parameters import ParameterVector
from abs.render.compiled import CompiledScene
from abs.render.path_lengths import MAX_MATERIALS

__all__ = ["FitProblem", "render_views"]

#: Memory for a problem's path-length recordings (bytes; 31 MB each at 320x240): the least
#: recently used go first.
RECORDING_BYTES = 4 << 30


def _view_seed(seed: int, view: int) -> int:
    """The render seed of view number ``view`` for a call seeded ``seed`` (spp batches add 0, 1,
    ...): distinct per view, and the same in every method, so residuals, Jacobians and gradients
    seeded alike see the same samples."""
    return seed * 1009 + view * 101


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
    counter : RenderCounter
        Where renders are counted (shared by the problems of one model).
    reweight : bool
        Use path-length recordings (:mod:`abs.render.path_lengths`) when some fitted parameter
        reweights from one (:attr:`reweightable`).
    """

    compiled: CompiledScene
    vector: ParameterVector
    observations: list[Observation]
    clamp: float | None = None
    max_depth: int | None = None
    counter: RenderCounter = field(default_factory=RenderCounter)
    reweight: bool = True
    _recordings: OrderedDict = field(default_factory=OrderedDict, repr=False)
    _weights: list | None = field(init=False, default=None, repr=False)

    def __post_init__(self) -> None:
        self._weights = pixel_weights(self.observations)

    @property
    def weights(self) -> list[np.ndarray] | None:
        """Per observation, the ``(H, W, 3)`` weights of its residuals (0 outside the mask), or
        ``None`` when pixels weigh alike (:func:`~abs.model.observations.pixel_weights`)."""
        return self._weights

    def _row_weights(self, k: int) -> np.ndarray | None:
        """Observation ``k``'s weights in residual order (masked pixels, channels), or None."""
        if self._weights is None:
            return None
        return self._weights[k][self.observations[k].mask].ravel()

    @property
    def n_residuals(self) -> int:
        return 3 * sum(o.pixels for o in self.observations)

    # --------------------------------------------------------- recordings
    def _absorption_owners(self) -> list[str]:
        """The materials whose absorption is fitted, sorted."""
        return sorted({self.compiled.specs[n].owner for n in self.vector.names
                       if self.compiled.specs[n].reweighting == "absorption"})

    @property
    def recorded_materials(self) -> tuple[str, ...]:
        """The glasses whose path lengths recordings keep: the owners of the fitted absorptions,
        one length each (a joint histogram, :mod:`abs.render.path_lengths`), the first
        ``MAX_MATERIALS`` by name when more are fitted (the others then change the paths' weights
        in ways the recorded lengths cannot reweight, and are rendered like an IOR); empty when
        no absorption is fitted."""
        return tuple(self._absorption_owners()[:MAX_MATERIALS])

    @property
    def reweightable(self) -> list[str]:
        """The fitted parameters whose values a path-length recording gives without a render (the
        absorptions of :attr:`recorded_materials`, the environment's scale, a sensor parameter), in
        the vector's order; empty when recordings are off. Renders are recordings whenever this
        is not empty."""
        if not self.reweight:
            return []
        others = set(self.compiled.needs_render(self.vector.names, self.recorded_materials))
        return [n for n in self.vector.names if n not in others]

    @property
    def uses_recordings(self) -> bool:
        """Whether every fitted parameter is :attr:`reweightable`. Then a render at another value
        of them is a reweighting, and only a new seed (or spp) renders: a fit's Jacobians, line
        searches and a sampler's likelihood evaluations render nothing."""
        reweightable = self.reweightable
        return bool(reweightable) and len(reweightable) == len(self.vector.names)

    def _fingerprint(self) -> str:
        """A digest of every compiled value a recording depends on (those it cannot reweight),
        so that a recording is never reused after something else changed the scene."""
        materials = self.recorded_materials
        digest = hashlib.sha1()
        for name in sorted(self.compiled.values):
            if self.compiled.needs_render([name], materials):
                digest.update(name.encode())
                digest.update(self.compiled.get(name).tobytes())
        return digest.hexdigest()

    def _recording(self, observation: Observation, spp: int, seed: int):
        """The recording of one view with ``(spp, seed)``, made on first use (one render)."""
        key = (observation.name, spp, seed, self._fingerprint())
        if key in self._recordings:
            self._recordings.move_to_end(key)
            return self._recordings[key]
        recording = self.compiled.record(observation.camera, spp, seed,
                                         materials=self.recorded_materials,
                                         max_depth=self.max_depth)
        self.counter.add(observation.camera, spp)
        self._recordings[key] = recording
        while (len(self._recordings) > 1
               and sum(r.nbytes for r in self._recordings.values()) > RECORDING_BYTES):
            self._recordings.popitem(last=False)
        return recording

    # ------------------------------------------------------------- values
    def set_values(self, theta: np.ndarray) -> None:
        """Write physical values (detached) into the compiled scene."""
        for name, value in self.vector.split(theta).items():
            self.compiled.set(name, value)

    def render(self, observation: Observation, theta: np.ndarray, spp: int, seed: int) -> np.ndarray:
        """Primal rendering (H, W, 3) of one observation at ``theta``."""
        self.set_values(theta)
        if self.reweightable:
            recording = self._recording(observation, spp, seed)
            with dr.suspend_grad():
                image = self.compiled.render_recorded(recording, observation.camera).numpy()
            return image.astype(np.float64)
        with dr.suspend_grad():
            image = self.compiled.render(observation.camera, spp=spp, seed=seed,
                                         max_depth=self.max_depth).numpy()
        self.counter.add(observation.camera, spp)
        return image.astype(np.float64)

    # ---------------------------------------------------------- residuals
    def noise_correlation(self):
        """``K @ X`` for matrices ``X`` (M, n) over the residuals' rows, ``K`` the correlation of
        the pixel noise between residuals: views whose cameras render a built capture's
        processing (a footprint) have noise spread between neighbouring pixels by demosaicing
        and resampling (:meth:`abs.render.footprint.FootprintFilm.correlate`), other views
        independent noise (``K = I``). ``None`` when no view has a footprint."""
        if all(o.camera.footprint is None for o in self.observations):
            return None

        def apply(X: np.ndarray) -> np.ndarray:
            X = np.asarray(X, np.float64)
            out, offset = np.empty_like(X), 0
            for obs in self.observations:
                n = 3 * obs.pixels
                block = X[offset:offset + n]
                if obs.camera.footprint is not None:
                    full = np.zeros((obs.mask.size, 3, X.shape[1]))
                    full[obs.mask.ravel()] = block.reshape(-1, 3, X.shape[1])
                    block = obs.camera.film().correlate(full)[obs.mask.ravel()].reshape(n, -1)
                out[offset:offset + n] = block
                offset += n
            return out

        return apply

    def _clamp(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The image as compared, and where it carries derivatives (not clamped)."""
        if self.clamp is None:
            return image, np.ones_like(image, bool)
        return np.minimum(image, self.clamp), image < self.clamp

    def _compare(self, k: int, image: np.ndarray):
        """Residuals of observation ``k`` (weighted) and the mask of residuals that carry
        derivatives, times the weights: what the Jacobian's rows are multiplied by."""
        observation = self.observations[k]
        clamped, live = self._clamp(image)
        m = observation.mask
        r, live = (clamped - observation.photograph)[m].ravel(), live[m].ravel().astype(np.float64)
        w = self._row_weights(k)
        return (r, live) if w is None else (r * w, live * w)

    def residuals(self, theta: np.ndarray, spp: int, seed: int, jacobian: bool = False,
                  jacobian_seed: int | None = None, names=None):
        """Residual vector at physical ``theta`` and, optionally, its Jacobian.

        With ``jacobian_seed`` (different from ``seed``) the Jacobian comes from an independent
        render. Residuals and Jacobian from the same render are correlated through the Monte-Carlo
        noise, which biases ``J^T r`` (the gradient) towards darker, less noisy renderings;
        independent renders make ``J^T r`` unbiased. ``names`` restricts the Jacobian to those
        parameters' columns (the others are zero).

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
                r, _ = self._compare(k, self.render(obs, theta, spp, view_seed))
                rs.append(r)
                continue
            image, jac = self._render_with_jacobian(
                obs, theta, spp, view_seed if jacobian_seed is None else _view_seed(jacobian_seed, k),
                names)
            if jacobian_seed is not None and jacobian_seed != seed:
                image = self.render(obs, theta, spp, view_seed)
            r, live = self._compare(k, image)
            rs.append(r)
            js.append(jac[obs.mask].reshape(-1, self.vector.size) * live[:, None])
        return np.concatenate(rs), (np.concatenate(js) if jacobian else None)

    def jacobian(self, theta: np.ndarray, spp: int, seed: int, names=None) -> np.ndarray:
        """The Jacobian (M, P) alone, from renders seeded ``seed`` (as :meth:`residuals` would
        seed them); the clamp mask comes from the same renders.

        Two Jacobians from different seeds give an unbiased estimate of ``J^T J`` as
        ``(J1^T J2 + J2^T J1) / 2``: the product of one noisy Jacobian with itself is inflated by
        the Jacobian's Monte-Carlo variance (measured: 3x at 16 spp for an IOR), which shortens
        Gauss-Newton steps and understates standard errors.
        """
        js = []
        for k, obs in enumerate(self.observations):
            image, jac = self._render_with_jacobian(obs, theta, spp, _view_seed(seed, k), names)
            live = self._compare(k, image)[1]
            js.append(jac[obs.mask].reshape(-1, self.vector.size) * live[:, None])
        return np.concatenate(js)

    def column_passes(self, names=None) -> list[tuple[np.ndarray, list[tuple[int, int | None]]]]:
        """How the Jacobian's columns are rendered: one forward-mode render per entry.

        Returns a list of ``(tangent, columns)``: ``tangent`` over all of the vector's scalars,
        and the columns that render gives, ``(scalar index, image channel or None)``. A
        parameter whose channels are separable (``Parameter.separable_channels``: an absorption
        or IOR per colour channel changes that channel of the image only) takes one render along
        ``(1, 1, 1)``, whose channel ``c`` is column ``c``; every other scalar takes its own.
        ``names`` restricts the passes to some parameters (default: all).
        """
        passes = []
        for name, s in self.vector.slices().items():
            if names is not None and name not in names:
                continue
            if self.compiled.specs[name].separable_channels and s.stop - s.start == 3:
                tangent = np.zeros(self.vector.size)
                tangent[s] = 1.0
                passes.append((tangent, [(s.start + c, c) for c in range(3)]))
                continue
            for i in range(s.start, s.stop):
                tangent = np.zeros(self.vector.size)
                tangent[i] = 1.0
                passes.append((tangent, [(i, None)]))
        return passes

    def _render_with_jacobian(self, obs: Observation, theta, spp: int, seed: int, names=None):
        cam, p = obs.camera, self.vector.size
        self.set_values(theta)
        reweightable = self.reweightable
        recording = self._recording(obs, spp, seed) if reweightable else None
        image, jac = None, np.zeros((cam.height, cam.width, 3, p))
        if recording is not None:  # the image every column's pass stands for
            with dr.suspend_grad():
                image = self.compiled.render_recorded(recording, cam).numpy().astype(np.float64)
        for tangent, columns in self.column_passes(names):
            # Every pass renders with the same seed (the same samples), and every fitted
            # parameter is given a tangent (zero where not wanted), so that every column is
            # rendered alike (e.g. dispersive glass splits its paths in each).
            tangents = self.vector.tangents(tangent)
            moved = {n for n, t in tangents.items() if np.any(np.asarray(t) != 0)}
            if recording is not None and moved <= set(reweightable):
                rendered, derivative = self.compiled.render_recorded_forward(
                    recording, cam, {n: tangents[n] for n in reweightable})
            else:
                # With a recording the image is its reweighting: an IOR's two-sided difference
                # then needs no render at p (2 renders instead of 3; the glass suite's
                # sphere-1.52: 947 renders instead of 1235).
                needed = recording is None
                rendered, derivative = self.compiled.render_forward(
                    cam, tangents, spp=spp, seed=seed, max_depth=self.max_depth,
                    image_needed=needed)
                for _ in range(self.compiled.forward_renders(tangents, image_needed=needed)):
                    self.counter.add(cam, spp)
            if image is None:
                image = rendered.numpy().astype(np.float64)
            derivative = derivative.numpy()
            for i, channel in columns:
                if channel is None:
                    jac[..., i] = derivative
                else:
                    jac[..., channel, i] = derivative[..., channel]
        if image is None:  # no column asked for
            image = self.render(obs, theta, spp, seed)
        return image, jac

    def gradient(self, theta: np.ndarray, spp: int, seed: int,
                 jacobian_seed: int) -> tuple[float, np.ndarray]:
        """Half the sum of squared residuals and its gradient ``J^T r`` w.r.t. ``theta``.

        ``r`` comes from the render seeded ``seed`` and ``J`` from the independent renders seeded
        ``jacobian_seed``, as in :meth:`residuals` (so ``J^T r`` is unbiased); the result equals
        ``J.T @ r`` of ``residuals(theta, spp, seed, True, jacobian_seed)``. Parameters that only
        scale what paths carry (textures, BRDF tables, absorption, the environment) take one path
        replay per view, whatever their number; parameters that move paths (IOR, roughness,
        pose) take one forward-mode render per scalar.
        """
        if self.uses_recordings:  # the Jacobian is free: no replay needed
            r, J = self.residuals(theta, spp, seed, jacobian=True, jacobian_seed=jacobian_seed)
            return 0.5 * float(r @ r), J.T @ r
        slices = self.vector.slices()
        replayed = [n for n in self.vector.names if not self.compiled.specs[n].moves_paths]
        moving = [n for n in self.vector.names if self.compiled.specs[n].moves_paths]
        total, grad = 0.0, np.zeros(self.vector.size)
        for k, obs in enumerate(self.observations):
            cam = obs.camera
            image = self.render(obs, theta, spp, _view_seed(seed, k))
            r, _ = self._compare(k, image)
            total += 0.5 * float(r @ r)
            clamped, live = self._clamp(image)
            residual = (clamped - obs.photograph) * (obs.mask[..., None] & live)
            if self._weights is not None:  # d/dtheta of (w r)^2 / 2 is w^2 r dr/dtheta
                residual = residual * np.square(self._weights[k])
            view_seed = _view_seed(jacobian_seed, k)
            if replayed:
                _, g = self.compiled.render_backward(cam, residual, replayed, spp=spp, seed=view_seed,
                                                     max_depth=self.max_depth)
                self.counter.add(cam, spp)
                for name in replayed:
                    # A tied parameter's one scalar moves every channel: the channels' sum.
                    grad[slices[name]] += (np.sum(g[name]) if name in self.vector.tied else g[name])
            for tangent, columns in self.column_passes(moving):
                tangents = self.vector.tangents(tangent, moving)
                # The image is the render above: an IOR's two-sided difference skips p's.
                _, derivative = self.compiled.render_forward(
                    cam, tangents, spp=spp, seed=view_seed, max_depth=self.max_depth,
                    image_needed=False)
                for _ in range(self.compiled.forward_renders(tangents, image_needed=False)):
                    self.counter.add(cam, spp)
                derivative = derivative.numpy() * residual
                for i, channel in columns:
                    grad[i] += float(np.sum(derivative if channel is None else derivative[..., channel]))
        self.set_values(theta)
        return total, grad


def render_views(problem: FitProblem, observations: list[Observation], theta: np.ndarray, spp: int,
                 seed: int) -> dict[str, np.ndarray]:
    """Renderings of ``observations`` at ``theta`` by name, view ``i`` seeded ``seed + 7 i``: a fit's
    before/after images (and the diagnosis's holdout renders) are made this one way, so that they
    share their Monte-Carlo noise.

    Parameters
    ----------
    problem : FitProblem
        Renders (its clamp is not applied: these are the images as rendered).
    observations : list of Observation
    theta : ndarray, shape (P,)
        Physical parameter values (the vector's units).
    spp : int
        Samples per pixel.
    seed : int
        Base seed.

    Returns
    -------
    dict of str to ndarray, shape (H, W, 3)
        Linear RGB.
    """
    return {o.name: problem.render(o, theta, spp, seed + 7 * i) for i, o in enumerate(observations)}
