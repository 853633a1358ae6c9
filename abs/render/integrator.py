"""abs's path tracer: unidirectional path tracing with environment importance sampling and MIS,
differentiated by plain reverse-mode AD with *attached* sampling.

Why our own integrator: Mitsuba's ``prb`` family detaches sampled directions by design, so the
gradient of an image with respect to a refractive index (which moves refracted directions) is
lost, and C++ ``path`` drops the direction's gradient too (shared/docs/mitsuba-facts.md). Here the
direction returned by every BSDF sample stays on the AD graph, so IOR, absorption, environment
(scale, rotation), reflectance and pose gradients all follow from one code path. Memory grows
with the recorded graph, so AD renders use small images or few samples per pass.

Pieces:

- Pixels: sample positions are drawn from a tent filter of radius 1 pixel around each pixel centre
  (each pixel integrates ``tent(x - p) L(x)``).
- Colour-channel passes: glass with a different IOR per channel renders three passes, pass ``k``
  refracting with ``ior[k]`` and contributing channel ``k`` (see :mod:`abs.render.bsdfs.dielectric`).
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
- Russian roulette from depth ``rr_depth`` on, with detached survival probabilities.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

from abs.render.bsdfs.dielectric import DielectricBSDF
from abs.render.camera import Camera
from abs.render.environment import Environment
from abs.render.edges import MovingMesh, boundary_term
from abs.render.jit import seed32

__all__ = ["PathTracer"]


def _mis_power(a, b):
    a2, b2 = dr.square(a), dr.square(b)
    return dr.select(a2 + b2 > 0.0, a2 / (a2 + b2), 0.0)



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
               moving: list[MovingMesh] | None = None, channels: str = "auto") -> mi.TensorXf:
        """Render one view; returns a linear-RGB ``TensorXf`` of shape ``(height, width, 3)``.

        The result stays attached to the AD graph of any parameter with gradients enabled.

        Parameters
        ----------
        spp : int
            Samples per pixel (per colour pass).
        seed : int
            Seed of the sample sequence; the same seed gives the same noise (common random numbers).
        moving : list of MovingMesh, optional
            Meshes whose vertices are attached to differentiated parameters: their silhouettes'
            boundary term is added to the gradient.
        channels : {"auto", "single", "per-channel"}
            ``auto`` renders per-channel passes only when some glass has distinct per-channel IORs
            or an IOR being differentiated.
        """
        glass = [s.bsdf() for s in scene.shapes() if isinstance(s.bsdf(), DielectricBSDF)]
        per_channel = channels == "per-channel" or (channels == "auto" and any(
            dr.grad_enabled(b.ior) or len({float(c[0]) for c in (b.ior.x, b.ior.y, b.ior.z)}) > 1
            for b in glass))
        if not per_channel:
            return self._render_pass(scene, env, camera, spp, seed, moving, channel=0)
        result = None
        for k in range(3):
            image = self._render_pass(scene, env, camera, spp, seed * 3 + k, moving, channel=k)
            mask = mi.TensorXf(dr.tile(mi.Float([1.0 if c == k else 0.0 for c in range(3)]),
                                       camera.width * camera.height), image.shape)
            result = image * mask if result is None else result + image * mask
        return result

    # --------------------------------------------------------------- private
    def _render_pass(self, scene, env, camera, spp, seed, moving, channel) -> mi.TensorXf:
        w, h = camera.width, camera.height
        n = w * h * spp
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed32(seed), n)
        idx = dr.arange(mi.UInt32, n)
        pixel = idx // spp
        px = mi.Float(pixel % w)
        py = mi.Float(pixel // w)
        offset = sampler.next_2d()
        dx = mi.warp.interval_to_tent(offset.x)
        dy = mi.warp.interval_to_tent(offset.y)
        if camera.block > 1:
            # A pixel of a downsampled camera is the box average of block x block fine pixels,
            # each with its tent filter: pick a fine pixel, then a tent offset of its size.
            if moving:
                raise NotImplementedError("pose gradients (edge sampling) need block == 1: fit "
                                          "poses without --downsample")
            b = camera.block
            pick = dr.floor(sampler.next_2d() * b)
            dx = (pick.x - (b - 1) / 2 + dx) / b
            dy = (pick.y - (b - 1) / 2 + dy) / b
        origin, d = camera.rays(px + dx, py + dy)
        # The ray time carries the colour channel of this pass to abs_dielectric (see there).
        ray = mi.Ray3f(origin, d, float(channel), mi.Color0f())
        radiance = self._trace(scene, env, ray, sampler)
        # Each pixel owns exactly spp consecutive samples: a block sum is the pixel estimate.
        values = [dr.block_sum(c, spp) / spp for c in (radiance.x, radiance.y, radiance.z)]
        flat = dr.zeros(mi.Float, w * h * 3)
        lane = dr.arange(mi.UInt32, w * h)
        for c in range(3):
            dr.scatter(flat, values[c], lane * 3 + c)
        image = mi.TensorXf(flat, (h, w, 3))
        if moving:
            image = image + boundary_term(self, scene, env, camera, moving,
                                          n_samples=2 * spp * (w + h), seed=seed, channel=channel)
        return image

    def _trace(self, scene, env: Environment, ray: mi.Ray3f, sampler: mi.Sampler) -> mi.Color3f:
        ctx = mi.BSDFContext()
        result = mi.Color3f(0.0)
        beta = mi.Color3f(1.0)
        active = mi.Bool(True)
        prev_pdf = mi.Float(1.0)
        prev_delta = mi.Bool(True)
        for depth in range(self.max_depth):
            si = scene.ray_intersect(ray, mi.RayFlags.All, depth == 0, active)
            escaped = active & ~si.is_valid()
            mis = dr.select(prev_delta, 1.0, _mis_power(prev_pdf, env.pdf(ray.d, escaped)))
            result += dr.select(escaped, beta * env.eval(ray.d, escaped, ray.o) * mis, 0.0)
            active &= si.is_valid()
            if depth + 1 >= self.max_depth:
                break
            if self.subsurface:
                si, score = self._spread(scene, si, ray, sampler, active)
                beta *= score
            bsdf = si.bsdf(ray)

            # Next-event estimation towards the environment (smooth lobes only).
            smooth = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            d_light, pdf_light = env.sample(sampler.next_2d(smooth), smooth)
            visible = smooth & (pdf_light > 0.0) & ~scene.ray_test(si.spawn_ray(d_light), smooth)
            f, pdf_bsdf = bsdf.eval_pdf(ctx, si, si.to_local(d_light), visible)
            contribution = beta * f * env.eval(d_light, visible, si.p) * \
                _mis_power(pdf_light, pdf_bsdf) / dr.select(visible, pdf_light, 1.0)
            result += dr.select(visible, contribution, 0.0)

            # Continue the path with an attached BSDF sample.
            bs, weight = bsdf.sample(ctx, si, sampler.next_1d(active), sampler.next_2d(active), active)
            beta *= dr.select(active, weight, 0.0)
            prev_pdf = bs.pdf
            prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            ray = si.spawn_ray(si.to_world(bs.wo))
            active &= (bs.pdf > 0.0) & (dr.max(dr.detach(beta)) > 0.0)

            if depth + 1 >= self.rr_depth:
                q = dr.minimum(dr.max(dr.detach(beta)), 0.95)
                survive = sampler.next_1d(active) < q
                beta = dr.select(survive, beta / dr.select(q > 0.0, q, 1.0), 0.0)
                active &= survive
        return result

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
