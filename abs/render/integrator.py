"""abs's path tracer: unidirectional path tracing with environment importance sampling and MIS,
as one symbolic Dr.Jit loop, differentiated with *attached* sampling.

Why our own integrator: Mitsuba's ``prb`` family detaches sampled directions by design, so the
gradient of an image with respect to a refractive index (which moves refracted directions) is
lost, and C++ ``path`` drops the direction's gradient too (shared/docs/mitsuba-facts.md). Here the
direction returned by every BSDF sample stays differentiable, so IOR, absorption, environment
(scale, rotation), reflectance and pose derivatives all follow from one code path.

Three modes and a replay, one loop body (:meth:`PathTracer._step`):

- ``primal``: a symbolic loop (``dr.while_loop``). The body is traced once and compiled into one
  kernel whatever ``max_depth`` is, so the first render compiles in about a second (the unrolled
  Python loop this replaced took 111 s for the default scene) and renders run at the speed of
  Mitsuba's own ``path`` (``benchmarks/render_speed.py``).
- ``forward``: forward-mode derivatives carried *inside* the symbolic loop. The loop state holds,
  beside the ray origin and direction, throughput and previous BSDF pdf, their tangents; each
  iteration makes the incoming state fresh AD leaves carrying those tangents, runs the body with
  gradients on, and reads the outgoing tangents with ``dr.forward_to``. Parameters enter with the
  tangents the caller pushed into them beforehand (:meth:`CompiledScene.render_forward`). Memory
  is the loop state's, twice over: it does not grow with path length, samples or the number of
  parameters, and one Jacobian column costs about 1.6 primal renders.
- ``recorded``: an evaluated loop whose iterations are recorded on the AD graph, so that
  ``dr.backward`` and ``dr.forward_to`` work on the returned image as on any Dr.Jit expression.
  Used automatically when a parameter has gradients enabled (interactive use, tests); memory
  grows with the samples in flight.
- reverse mode by path replay (:meth:`PathTracer.render_backward`, Vicini et al. 2021): a primal
  pass, then the same paths again, backpropagating each vertex's contribution. Constant memory,
  about two primal renders, exact for every parameter whose derivative stays at its vertex
  (textures, BRDF tables, absorption, environment); parameters that move paths (IOR, roughness,
  pose) take forward mode.
- recording (:meth:`PathTracer.record`): a primal pass that bins every vertex's light by the
  length its path has travelled inside one glass, so that the image at any absorption of that
  glass follows without rendering (:mod:`abs.render.path_lengths`).

Pieces:

- Pixels: sample positions are drawn from a tent filter of radius 1 pixel around each pixel centre
  (each pixel integrates ``tent(x - p) L(x)``). A camera with a footprint (photographs built from a
  sensor, :mod:`abs.acquisition.footprint`) renders the sensor's sites instead, each from samples
  in its square, and makes its pixels from them with the build's own weights
  (:mod:`abs.render.footprint`): the build's demosaicing and undistortion, exactly.
- Dispersion: a path carries all three colour channels until it first meets glass whose IOR
  differs between channels (or is being differentiated). There it picks one channel uniformly,
  keeps only that channel with weight 3 (an unbiased estimate of the three), and refracts with
  that channel's IOR from then on (see :mod:`abs.render.bsdfs.dielectric`). Paths that never
  reach glass keep their full colour: unlike one render per channel, the cost of dispersion is
  paid only where it acts. The active channel travels per lane in ``si.time`` (3: not yet split).
- Lighting: the environment (:class:`~abs.render.environment.Environment`) is evaluated by our
  differentiable lookup, sampled by luminance; BSDF and light samples are combined with the power
  heuristic. The weights stay *attached*: BSDF samples are differentiated in primary-sample
  space and light samples in direction space, and only attached weights keep summing to one
  under differentiation (detached weights bias gradients whenever a shading frame moves).
- Visibility: when meshes move (pose), the boundary term of their silhouettes is added by edge
  sampling (:mod:`abs.render.edges`); shadow and refracted silhouettes are not handled.
- Subsurface spread (``diffuse`` materials' ``subsurface``, see :meth:`PathTracer._spread`): light
  leaves a diffuse surface at a point displaced from where it arrived by a 2-D Gaussian in the
  tangent plane, which blurs shading, shadows and caustics on it.
- Russian roulette from depth ``rr_depth`` on, with detached survival probabilities computed from
  the path's throughput *without the weights of its specular (glass) vertices*: so the decisions
  do not depend on a glass's absorption or IOR. A render at absorption ``sigma`` then makes the
  very same random decisions as a path-length recording at any other absorption, and the
  recording reweighted to ``sigma`` is that render (up to the length binning; with the glass's
  absorption in the throughput they differed by 3e-3 RMS on the sampling benchmark's views, a
  tenth of the residual, enough to move a posterior by 0.45 sd). It also keeps the decisions
  common to both sides of an IOR's central difference.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

from abs.render.bsdfs.dielectric import DielectricBSDF
from abs.render.camera import Camera
from abs.render.environment import Environment
from abs.render.edges import MovingMesh, boundary_term
from abs.render.jit import opaque, seed32
from abs.render.path_lengths import bin_light

__all__ = ["PathTracer", "MODES"]

MODES = ("primal", "forward", "recorded")

# The channel value of a path that has not met dispersive glass yet (see the module docstring).
_ALL_CHANNELS = 3


def _mis_power(a, b):
    a2, b2 = dr.square(a), dr.square(b)
    return dr.select(a2 + b2 > 0.0, a2 / (a2 + b2), 0.0)


def _leaf(value, tangent):
    """A fresh AD leaf with ``value``'s (detached) value and ``tangent`` as its gradient."""
    x = type(value)(dr.detach(value))
    dr.enable_grad(x)
    dr.set_grad(x, tangent)
    return x


def _boosted_pixel(boost, index: mi.UInt32, width: mi.UInt32) -> mi.UInt32:
    """The flat pixel index (row-major, ``width`` columns) of the ``index``-th pixel of
    ``boost``'s rectangle, row by row: where its extra lanes go."""
    columns = opaque(mi.UInt32, boost.x1 - boost.x0)
    return ((opaque(mi.UInt32, boost.y0) + index // columns) * width
            + opaque(mi.UInt32, boost.x0) + index % columns)


def _in_boost(boost, pixel: mi.UInt32, width: mi.UInt32) -> mi.Bool:
    """Whether each flat pixel index (row-major, ``width`` columns) lies in ``boost``'s
    rectangle."""
    x, y = pixel % width, pixel // width
    return ((x >= opaque(mi.UInt32, boost.x0)) & (x < opaque(mi.UInt32, boost.x1))
            & (y >= opaque(mi.UInt32, boost.y0)) & (y < opaque(mi.UInt32, boost.y1)))


@dataclass
class PathTracer:
    """Render images of a Mitsuba scene lit by an :class:`Environment`.

    Parameters
    ----------
    max_depth : int
        Maximum number of path segments (1: environment seen directly).
    rr_depth : int
        Depth from which Russian roulette may end paths.
    subsurface : list of (ShapePtr, Float)
        Shapes whose surface spreads light, each with its spread (standard deviation per tangent
        axis, metres, a width-1 ``Float`` that may be attached to the AD graph).
    """

    max_depth: int = 12
    rr_depth: int = 5
    subsurface: list = field(default_factory=list)

    # ---------------------------------------------------------------- public
    def render(self, scene: mi.Scene, env: Environment, camera: Camera, spp: int, seed: int = 0,
               moving: list[MovingMesh] | None = None, dispersion: str = "auto") -> mi.TensorXf:
        """Render one view; returns a linear-RGB ``TensorXf`` of shape ``(height, width, 3)``.

        When any input has gradients enabled (and gradients are not suspended), the render is
        recorded on the AD graph (``recorded`` mode, see the module docstring) so that
        ``dr.backward``/``dr.forward_to`` work on the result; otherwise it is a primal render.

        Parameters
        ----------
        spp : int
            Samples per pixel.
        seed : int
            Seed of the sample sequence; the same seed gives the same noise (common random numbers).
        moving : list of MovingMesh, optional
            Meshes whose vertices are attached to differentiated parameters: their silhouettes'
            boundary term is added to the gradient.
        dispersion : {"auto", "split", "none"}
            ``auto`` splits paths by colour channel at dispersive glass only when some glass has
            distinct per-channel IORs or an IOR with gradients enabled.
        """
        self._check_moving(camera, moving)
        split = self._split(scene, dispersion)
        mode = "recorded" if (moving or self._attached(scene, env)) else "primal"
        image, _ = self._render_pass(scene, env, camera, spp, seed, split, mode)
        if moving:
            image = image + boundary_term(self, scene, env, camera, moving,
                                          n_samples=2 * spp * (camera.width + camera.height),
                                          seed=seed, split=split)
        return image

    def render_forward(self, scene: mi.Scene, env: Environment, camera: Camera, spp: int,
                       seed: int = 0, moving: list[MovingMesh] | None = None,
                       dispersion: str = "auto") -> tuple[mi.TensorXf, mi.TensorXf]:
        """Render one view and its forward-mode derivative.

        The scene's parameters must already hold their tangents as gradients, with no AD edges
        leading into them (push a tangent from your own leaf with ``dr.enqueue`` and
        ``dr.traverse(dr.ADMode.Forward, dr.ADFlag.ClearEdges)``; :meth:`CompiledScene.render_forward`
        does this). Returns detached ``(image, d image)``, both ``(height, width, 3)``.
        """
        self._check_moving(camera, moving)
        split = self._split(scene, dispersion)
        image, tangent = self._render_pass(scene, env, camera, spp, seed, split, "forward")
        if moving:
            with dr.resume_grad():
                edges = boundary_term(self, scene, env, camera, moving,
                                      n_samples=2 * spp * (camera.width + camera.height), seed=seed,
                                      split=split)
                tangent = tangent + dr.forward_to(edges, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
        return image, dr.detach(tangent)

    def trace(self, scene: mi.Scene, env: Environment, ray: mi.Ray3f, sampler: mi.Sampler,
              split: bool = False, mode: str = "primal") -> tuple[mi.Color3f, mi.Color3f | None]:
        """Radiance arriving along ``ray`` (one path per lane) and, in ``forward`` mode, its tangent.

        ``ray.time`` must be 3 (no channel chosen yet) or the one colour channel a path carries.
        """
        if mode not in MODES:
            raise ValueError(f"unknown mode {mode!r}; one of {', '.join(MODES)}")
        forward = mode == "forward"
        zero3 = mi.Vector3f(0.0)
        state = (sampler, mi.Ray3f(ray), mi.Color3f(1.0), mi.Color3f(0.0), mi.Bool(True),
                 mi.Float(1.0), mi.Bool(True), mi.UInt32(0),
                 # tangents of origin, direction, throughput, radiance and previous pdf
                 zero3, zero3, mi.Color3f(0.0), mi.Color3f(0.0), mi.Float(0.0),
                 mi.Color3f(1.0))  # Russian roulette's throughput (see _step)

        def cond(sampler, ray, beta, radiance, active, *rest):
            return active

        def body(sampler, ray, beta, radiance, active, prev_pdf, prev_delta, depth,
                 t_origin, t_direction, t_beta, t_radiance, t_pdf, roulette):
            if not forward:
                light, ray, beta, active, prev_pdf, prev_delta, _, roulette = self._step(
                    scene, env, sampler, ray, beta, active, prev_pdf, prev_delta, depth, split,
                    roulette=roulette)
                return (sampler, ray, beta, radiance + light, active, prev_pdf, prev_delta,
                        depth + 1, t_origin, t_direction, t_beta, t_radiance, t_pdf, roulette)
            with dr.resume_grad():
                ray_in = mi.Ray3f(_leaf(ray.o, t_origin), _leaf(ray.d, t_direction), ray.time,
                                  ray.wavelengths)
                light, ray_out, beta_out, active, pdf_out, prev_delta, _, roulette = self._step(
                    scene, env, sampler, ray_in, _leaf(beta, t_beta), active,
                    _leaf(prev_pdf, t_pdf), prev_delta, depth, split, roulette=roulette)
                # Not ClearInput: the parameters' tangents are sources of every iteration, and
                # clearing them here left only the first vertex differentiated in the parameters.
                grads = dr.forward_to(light, ray_out.o, ray_out.d, beta_out, pdf_out,
                                      flags=dr.ADFlag.ClearEdges | dr.ADFlag.ClearInterior
                                      | dr.ADFlag.AllowNoGrad)
            return (sampler, dr.detach(ray_out), dr.detach(beta_out), radiance + dr.detach(light),
                    active, dr.detach(pdf_out), prev_delta, depth + 1,
                    mi.Vector3f(grads[1]), mi.Vector3f(grads[2]), mi.Color3f(grads[3]),
                    t_radiance + mi.Color3f(grads[0]), mi.Float(grads[4]), dr.detach(roulette))

        out = dr.while_loop(state, cond, body, max_iterations=self.max_depth,
                            mode="evaluated" if mode == "recorded" else "symbolic",
                            label=f"abs path tracer ({mode})")
        return out[3], (out[11] if forward else None)

    def render_backward(self, scene: mi.Scene, env: Environment, camera: Camera, spp: int,
                        seed: int, adjoint, dispersion: str = "auto") -> mi.TensorXf:
        """Path replay backpropagation (Vicini et al. 2021) of one view; returns the primal image.

        Renders the view, asks ``adjoint(image)`` for the derivative of the loss with respect to
        the image (a ``TensorXf`` of the image's shape; it may itself backpropagate into other
        parameters, e.g. the sensor's), then traces every path again with the same samples and,
        at each vertex, backpropagates the loss through what that vertex contributes: its own
        light, and the light of the rest of the path through the vertex's sample weight. Memory
        is the loop state's; the cost is about two primal renders.

        Only derivatives that stay at their vertex are exact: BSDF and emitter values (textures,
        reflectance, measured-BRDF tables), absorption, the environment's scale, rotation,
        orientation and distance, subsurface spread. The replayed paths are detached, so parameters that move
        paths (IOR, roughness, pose: ``Parameter.moves_paths``) need :meth:`render_forward`.
        """
        split = self._split(scene, dispersion)
        with dr.suspend_grad():
            sampler, ray, _, _, film = self._camera_rays(camera, spp, seed)
            radiance, _ = self.trace(scene, env, ray, sampler, split, "primal")
            dr.eval(radiance)
            image = self._film(radiance, camera, spp, film)
        weight = adjoint(image).array
        sampler, ray, pixel, share, film = self._camera_rays(camera, spp, seed)
        if film is not None:
            per_sample = film.adjoint(weight, pixel, spp)
        else:
            inv_spp = opaque(mi.Float, 1.0 / spp) * (1.0 if share is None else share)
            per_sample = mi.Color3f(*[dr.gather(mi.Float, weight, pixel * 3 + c) * inv_spp
                                      for c in range(3)])
        self._trace_adjoint(scene, env, ray, sampler, split, radiance, per_sample)
        return image

    def _trace_adjoint(self, scene, env, ray, sampler, split, radiance, adjoint) -> None:
        """The replay loop of :meth:`render_backward`: ``radiance`` is each path's primal value
        and ``adjoint`` the loss's derivative with respect to it."""
        state = (sampler, mi.Ray3f(ray), mi.Color3f(1.0), mi.Color3f(radiance), mi.Bool(True),
                 mi.Float(1.0), mi.Bool(True), mi.UInt32(0), mi.Color3f(1.0))

        def cond(sampler, ray, beta, remaining, active, *rest):
            return active

        def body(sampler, ray, beta, remaining, active, prev_pdf, prev_delta, depth, roulette):
            with dr.resume_grad():
                light, ray, beta_out, active, prev_pdf, prev_delta, _, roulette = self._step(
                    scene, env, sampler, ray, beta, active, prev_pdf, prev_delta, depth, split,
                    roulette=roulette)
                # What the rest of the path brings, and its derivative through this vertex's
                # weight (beta_out / detach(beta_out): 1 in value, d weight / weight attached).
                remaining = remaining - dr.detach(light)
                value = dr.detach(beta_out)
                relative = dr.select(value != 0.0, beta_out / dr.select(value != 0.0, value, 1.0), 0.0)
                dr.backward_from(adjoint * (light + remaining * relative),
                                 flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
            return (sampler, dr.detach(ray), value, remaining, active, dr.detach(prev_pdf),
                    prev_delta, depth + 1, dr.detach(roulette))

        dr.while_loop(state, cond, body, max_iterations=self.max_depth, label="abs path replay")

    def record(self, scene: mi.Scene, env: Environment, camera: Camera, spp: int, seed: int,
               glasses, bins, dispersion: str = "auto") -> mi.Float:
        """Render one view recording its light by in-glass path lengths (a primal render).

        Every vertex's light is binned at the total lengths its path has travelled inside each
        of ``glasses`` (BSDFs, one :class:`~abs.render.path_lengths.LengthBins` each in ``bins``)
        so far (:func:`~abs.render.path_lengths.bin_light`); the image at other absorptions of
        those glasses then follows without rendering (:func:`~abs.render.path_lengths.reweight`).
        The samples are those of :meth:`render` with the same ``seed``: at the recording's own
        absorptions the reweighted image is that render's, up to float rounding.

        Returns
        -------
        mi.Float
            ``height * width * 3 * prod(b.slots)`` floats: the histogram of
            :class:`~abs.render.path_lengths.PathLengthRecording` (divided by ``spp``).
        """
        split = self._split(scene, dispersion)
        slots = 1
        for b in bins:
            slots *= b.slots
        histogram = dr.zeros(mi.Float, camera.width * camera.height * 3 * slots)
        targets = tuple(opaque(mi.UInt32, dr.reinterpret_array(mi.UInt32, mi.BSDFPtr(g))[0])
                        for g in glasses)
        with dr.suspend_grad():
            sampler, ray, pixel, share, film = self._camera_rays(camera, spp, seed)
            state = (sampler, ray, mi.Color3f(1.0), mi.Bool(True), mi.Float(1.0), mi.Bool(True),
                     mi.UInt32(0), tuple(mi.Float(0.0) for _ in targets), mi.Color3f(1.0))

            def cond(sampler, ray, beta, active, *rest):
                return active

            def body(sampler, ray, beta, active, prev_pdf, prev_delta, depth, lengths, roulette):
                light, ray, beta, active, prev_pdf, prev_delta, glass_lengths, roulette = self._step(
                    scene, env, sampler, ray, beta, active, prev_pdf, prev_delta, depth, split,
                    glass_ids=targets, roulette=roulette)
                # This vertex's light has been attenuated along ``lengths``; the segment that
                # ended here (if in a glass) attenuates the light of the vertices after it.
                if film is None:
                    bin_light(histogram, pixel, light if share is None else light * share, lengths,
                              bins)
                else:
                    # Every pixel that uses this lane's site, with its weight, channel by channel.
                    for c, target, w in film.splats(pixel, spp):
                        one = [mi.Float(0.0)] * 3
                        one[c] = light[c] * w
                        bin_light(histogram, target, mi.Color3f(*one), lengths, bins)
                return (sampler, ray, beta, active, prev_pdf, prev_delta, depth + 1,
                        tuple(a + b for a, b in zip(lengths, glass_lengths)), roulette)

            dr.while_loop(state, cond, body, max_iterations=self.max_depth,
                          label="abs path tracer (recording)")
            histogram = histogram * opaque(mi.Float, 1.0 / spp)
            dr.eval(histogram)
        return histogram

    # --------------------------------------------------------------- private
    @staticmethod
    def _check_moving(camera: Camera, moving) -> None:
        if moving and camera.block > 1:
            raise NotImplementedError("pose and placement gradients (edge sampling) need block == 1: "
                                      "fit them without --downsample")

    @staticmethod
    def _split(scene: mi.Scene, dispersion: str) -> bool:
        if dispersion not in ("auto", "split", "none"):
            raise ValueError(f"dispersion must be 'auto', 'split' or 'none', not {dispersion!r}")
        if dispersion != "auto":
            return dispersion == "split"
        glass = [s.bsdf() for s in scene.shapes() if isinstance(s.bsdf(), DielectricBSDF)]
        return any(dr.grad_enabled(b.ior) or len({float(c[0]) for c in (b.ior.x, b.ior.y, b.ior.z)}) > 1
                   for b in glass)

    def _attached(self, scene: mi.Scene, env: Environment) -> bool:
        """Whether any input of a render has gradients enabled (and they are not suspended)."""
        values = [env.scale, env.rotation, env.orientation, env.inverse_distance, env.data]
        values += [value for _, value in self.subsurface]
        params = mi.traverse(scene)
        values += [params[k] for k in params.keys()]
        return any(dr.grad_enabled(v) for v in values)

    @staticmethod
    def _camera_rays(camera: Camera, spp: int, seed: int):
        """The sampler and camera rays of a render: ``spp`` consecutive lanes per pixel, then the
        extra lanes of a :class:`~abs.render.camera.SampleBoost` (``spp * (factor - 1)``
        consecutive ones per boosted pixel, row by row).

        Returns ``(sampler, ray, pixel, share, film)``: ``share`` is each lane's weight relative
        to ``1 / spp`` (``1 / factor`` in boosted pixels), ``None`` without a boost; ``film`` the
        camera's :class:`~abs.render.footprint.FootprintFilm` when it has a footprint (then
        ``pixel`` is each lane's sensor site), else ``None``. The same
        ``(camera, spp, seed)`` gives the same rays and the same sampler state, which path replay
        relies on; the lanes of the unboosted pixels are those of the camera without the boost.
        """
        w, h = camera.width, camera.height
        n = camera.samples(spp)
        sampler = mi.load_dict({"type": "independent"})
        # Sizes and seeds enter kernels as memory, not literals: another spp, resolution or seed
        # must reuse the compiled kernels.
        sampler.seed(opaque(mi.UInt32, seed32(seed)), n)
        lane = dr.arange(mi.UInt32, n)
        if camera.footprint is not None:
            film = camera.film()
            site, u, v = film.positions(sampler, lane, spp)
            origin, d = camera.rays(u, v)
            return sampler, mi.Ray3f(origin, d, float(_ALL_CHANNELS), mi.Color0f()), site, None, film
        pixel = lane // opaque(mi.UInt32, spp)
        width = opaque(mi.UInt32, w)
        share, boost = None, camera.boost
        if boost is not None:
            base = opaque(mi.UInt32, w * h * spp)
            extra = lane >= base
            j = dr.select(extra, lane - base, 0) // opaque(mi.UInt32, spp * (boost.factor - 1))
            pixel = dr.select(extra, _boosted_pixel(boost, j, width), pixel)
            share = dr.select(_in_boost(boost, pixel, width), opaque(mi.Float, 1.0 / boost.factor), 1.0)
        px = mi.Float(pixel % width)
        py = mi.Float(pixel // width)
        offset = sampler.next_2d()
        dx = mi.warp.interval_to_tent(offset.x)
        dy = mi.warp.interval_to_tent(offset.y)
        if camera.block > 1:
            # A pixel of a downsampled camera is the box average of block x block fine pixels,
            # each with its tent filter: pick a fine pixel, then a tent offset of its size.
            b = opaque(mi.Float, camera.block)
            pick = dr.floor(sampler.next_2d() * b)
            dx = (pick.x - (b - 1) / 2 + dx) / b
            dy = (pick.y - (b - 1) / 2 + dy) / b
        origin, d = camera.rays(px + dx, py + dy)
        return sampler, mi.Ray3f(origin, d, float(_ALL_CHANNELS), mi.Color0f()), pixel, share, None

    def _render_pass(self, scene, env, camera, spp, seed, split, mode):
        sampler, ray, _, _, film = self._camera_rays(camera, spp, seed)
        radiance, tangent = self.trace(scene, env, ray, sampler, split, mode)
        # Evaluate all channels in one launch: reducing channel by channel from the unevaluated
        # loop would run the whole path-tracing kernel once per channel.
        dr.eval(radiance, tangent)
        images = [self._film(radiance, camera, spp, film)]
        images.append(self._film(tangent, camera, spp, film) if tangent is not None else None)
        return images

    @staticmethod
    def _film(radiance: mi.Color3f, camera: Camera, spp: int, film=None) -> mi.TensorXf:
        """Each pixel's estimate from its lanes (:meth:`_camera_rays`)."""
        w, h = camera.width, camera.height
        if film is not None:
            return film.film(radiance, spp, w, h)
        inv_spp = opaque(mi.Float, 1.0 / spp)
        flat = dr.zeros(mi.Float, w * h * 3)
        lane = dr.arange(mi.UInt32, w * h)
        boost = camera.boost
        # Block sums, not atomic adds: the same samples give the same image, bit for bit. Each
        # pixel owns spp consecutive lanes, and each boosted pixel spp * (factor - 1) more after
        # all of those, row by row (see _camera_rays).
        if boost is not None:
            per = spp * (boost.factor - 1)
            width = opaque(mi.UInt32, w)
            target = _boosted_pixel(boost, dr.arange(mi.UInt32, boost.pixels), width)
            inside = _in_boost(boost, lane, width)
            ordinary_lanes = dr.arange(mi.UInt32, w * h * spp)
            extra_lanes = opaque(mi.UInt32, w * h * spp) + dr.arange(mi.UInt32, boost.pixels * per)
        for c, value in enumerate((radiance.x, radiance.y, radiance.z)):
            if boost is None:
                dr.scatter(flat, dr.block_sum(value, spp) * inv_spp, lane * 3 + c)
                continue
            ordinary = dr.block_sum(dr.gather(mi.Float, value, ordinary_lanes), spp)
            extra = dr.zeros(mi.Float, w * h)
            dr.scatter(extra, dr.block_sum(dr.gather(mi.Float, value, extra_lanes), per), target)
            # Inside: spp ordinary and spp (factor - 1) extra samples, averaged together.
            pixel_value = dr.select(inside, (ordinary + extra) * opaque(mi.Float, 1.0 / boost.factor),
                                    ordinary) * inv_spp
            dr.scatter(flat, pixel_value, lane * 3 + c)
        return mi.TensorXf(flat, (h, w, 3))

    def _step(self, scene, env: Environment, sampler, ray, beta, active, prev_pdf, prev_delta,
              depth, split, glass_ids=(), roulette=None):
        """One path vertex: light reaching the camera from it, and the continued path.

        Returns ``(light, ray, beta, active, prev_pdf, prev_delta, glass_lengths, roulette)``:
        ``glass_lengths`` holds, per BSDF registry id in ``glass_ids`` (``UInt32``), the length
        (m) of the segment that ended here if it ran inside that BSDF (the segment whose
        Beer-Lambert factor this vertex's sample weight applies), else 0. ``roulette`` (detached
        ``Color3f``, 1 at the camera) is the throughput that Russian roulette's survival
        probability follows: ``beta`` without the sample weights of specular vertices, so that
        no glass's absorption or IOR changes a decision (module docstring).
        """
        ctx = mi.BSDFContext()
        light = mi.Color3f(0.0)
        si = scene.ray_intersect(ray, mi.RayFlags.All, depth == 0, active)
        escaped = active & ~si.is_valid()
        mis = dr.select(prev_delta, 1.0, _mis_power(prev_pdf, env.pdf(ray.d, escaped)))
        light += dr.select(escaped, beta * env.eval(ray.d, escaped, ray.o) * mis, 0.0)
        active = active & si.is_valid() & (depth + 1 < self.max_depth)
        roulette = mi.Color3f(1.0) if roulette is None else roulette
        if self.subsurface:
            si, score = self._spread(scene, si, ray, sampler, active)
            beta = beta * score
            roulette = roulette * dr.detach(score)
        bsdf = si.bsdf(ray)
        channel = mi.UInt32(ray.time)
        if split:
            # The first dispersive glass a path meets picks the one channel it carries on with.
            glass = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.DeltaTransmission) & \
                (channel == _ALL_CHANNELS)
            chosen = dr.minimum(mi.UInt32(3.0 * sampler.next_1d(glass)), 2)
            channel = dr.select(glass, chosen, channel)
            keep = mi.Color3f(*[dr.select(channel == c, 3.0, 0.0) for c in range(3)])
            beta = dr.select(glass, beta * keep, beta)
        si.time = mi.Float(channel)
        glass_lengths = ()
        if glass_ids:
            # Compared as registry ids: pointer comparison fails inside symbolic loops.
            inside = active & (mi.Frame3f.cos_theta(si.wi) < 0.0)
            bsdf_id = dr.reinterpret_array(mi.UInt32, bsdf)
            glass_lengths = tuple(dr.select(inside & (bsdf_id == g), si.t, 0.0) for g in glass_ids)

        # Next-event estimation towards the environment (smooth lobes only).
        smooth = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        d_light, pdf_light = env.sample(sampler.next_2d(smooth), smooth)
        visible = smooth & (pdf_light > 0.0) & ~scene.ray_test(si.spawn_ray(d_light), smooth)
        f, pdf_bsdf = bsdf.eval_pdf(ctx, si, si.to_local(d_light), visible)
        contribution = beta * f * env.eval(d_light, visible, si.p) * \
            _mis_power(pdf_light, pdf_bsdf) / dr.select(visible, pdf_light, 1.0)
        light += dr.select(visible, contribution, 0.0)

        # Continue the path with an attached BSDF sample.
        bs, weight = bsdf.sample(ctx, si, sampler.next_1d(active), sampler.next_2d(active), active)
        beta = beta * dr.select(active, weight, 0.0)
        prev_pdf = bs.pdf
        prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        ray = si.spawn_ray(si.to_world(bs.wo))
        active &= (bs.pdf > 0.0) & (dr.max(dr.detach(beta)) > 0.0)
        roulette = dr.select(active & ~prev_delta, roulette * dr.detach(weight), roulette)

        played = active & (depth + 1 >= self.rr_depth)
        q = dr.minimum(dr.max(roulette), 0.95)
        survive = sampler.next_1d(played) < q
        q = dr.select(q > 0.0, q, 1.0)
        beta = dr.select(played, dr.select(survive, beta / q, 0.0), beta)
        roulette = dr.select(played & survive, roulette / q, roulette)
        active &= ~played | survive
        return light, ray, beta, active, prev_pdf, prev_delta, glass_lengths, roulette

    def _spread(self, scene, si, ray, sampler, active):
        """Move the shading point of surfaces with subsurface spread.

        The exit point is ``p + y`` projected back onto the same shape along its normal, with ``y``
        a Gaussian displacement in the tangent plane of standard deviation ``sigma`` per axis
        (falls back to ``p`` where the projection leaves the shape, e.g. beyond its edge).
        ``y`` is drawn detached and ``d/d sigma`` comes from the score function of its density:
        the returned factor is ``exp(log G(y) - detach(log G(y)))``, 1 in value with the gradient
        ``d log G / d sigma = (|y|^2 / sigma^2 - 2) / sigma``, which is unbiased even where the
        moving point crosses shadow or caustic boundaries (a moved point would miss those).

        Returns
        -------
        si : SurfaceInteraction3f
            The exit point's interaction (``wi`` still towards where the path came from).
        score : Float
            The score factor (1 in value).
        """
        sigma = mi.Float(0.0)
        for shape, value in self.subsurface:
            sigma = dr.select(si.shape == shape, value, sigma)
        spread = active & (sigma > 0.0)
        u = sampler.next_2d(spread)
        radius = dr.sqrt(-2.0 * dr.log(dr.maximum(1.0 - u.x, 1e-12)))
        sin_phi, cos_phi = dr.sincos(dr.two_pi * u.y)
        s = dr.detach(sigma)
        frame = dr.detach(si.sh_frame)
        y = s * radius * (cos_phi * frame.s + sin_phi * frame.t)
        n = dr.detach(si.n)
        lift = 3.0 * s * radius + 1e-4
        probe = mi.Ray3f(dr.detach(si.p) + y + lift * n, -n, 2.0 * lift, ray.time, mi.Color0f())
        moved = scene.ray_intersect(probe, mi.RayFlags.All, False, spread)
        ok = spread & moved.is_valid() & (moved.shape == si.shape)
        moved.wi = moved.to_local(-ray.d)
        moved.time = si.time
        safe = dr.select(spread, sigma, 1.0)  # no 0/0 (and NaN adjoints) on other lanes
        log_density = -dr.squared_norm(y) / (2.0 * dr.square(safe)) - 2.0 * dr.log(safe)
        score = dr.select(spread, dr.exp(log_density - dr.detach(log_density)), 1.0)
        return dr.select(ok, moved, si), score
