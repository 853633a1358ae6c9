"""AD-versus-finite-difference checks with Monte Carlo error bars.

Both estimates are noisy: the AD gradient is itself a Monte Carlo estimate, and a central finite
difference with common random numbers still jumps where a discrete sampling decision (reflect or
refract, Russian roulette) flips. So each is averaged over several seeds and the two must agree
within their combined standard error (plus a small relative slack), and the FD estimate must be
clearly nonzero so that the check cannot pass vacuously.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.integrator import PathTracer


def gradient_setup(scene_file, size: int, eye, target, fov_deg: float, weight_seed: int):
    """A compiled scene, a square ``size``-pixel camera at ``eye`` looking at ``target`` and
    random loss weights in [0, 1) (seeded ``weight_seed``): the fixture of the gradient tests."""
    from abs.camera.pinhole import intrinsics_from_fov, look_at
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    compiled = compile_scene(load_scene(scene_file))
    R, t = look_at(np.asarray(eye, float), np.asarray(target, float))
    camera = Camera(intrinsics_from_fov(size, size, np.radians(fov_deg)), R, t, size, size)
    weights = mi.TensorXf(np.random.default_rng(weight_seed).uniform(0, 1, (size, size, 3))
                          .astype(np.float32))
    return compiled, camera, weights


def directional_gradient(compiled, camera, name, direction, h, weights, seeds=4, spp=64,
                         max_depth=4, edges=True, full=False, mode="forward"):
    """(AD mean, AD s.e., FD mean, FD s.e.) of d loss / d(h-step along ``direction``).

    ``mode``: how the AD derivative is taken:

    - ``"forward"``: :meth:`CompiledScene.render_forward` (what fits use for Jacobians: tangents
      inside the path loop, silhouette boundary terms included; central differences with common
      random numbers for an IOR);
    - ``"tangents"``: :meth:`CompiledScene.render_forward` with ``differences=False`` (forward
      mode for every parameter, an IOR included);
    - ``"replay"``: :meth:`CompiledScene.render_backward` (path replay; what gradients of
      parameters that do not move paths use);
    - ``"recorded"``: ``dr.backward`` through a recorded render. ``edges=False`` leaves the
      silhouettes' boundary term out; ``full`` differentiates ``compiled.render`` (path tracer and
      ``[sensor]``) rather than the path tracer alone (without Russian roulette).

    The finite differences always difference ``compiled.render`` at ``x0 +- h direction`` with the
    AD estimate's seeds (common random numbers).
    """
    x0 = compiled.get(name)
    direction = np.asarray(direction, float)
    tracer = PathTracer(max_depth=max_depth, rr_depth=1000)
    weights_np = np.asarray(weights.numpy(), np.float64)

    def primal(x, seed):
        compiled.set(name, mi.Float(np.asarray(x, np.float32)))
        return float(np.sum(compiled.render(camera, spp=spp, seed=seed, max_depth=max_depth).numpy()
                            .astype(np.float64) * weights_np))

    def derivative(seed):
        if mode in ("forward", "tangents"):
            _, d = compiled.render_forward(camera, {name: direction}, spp=spp, seed=seed,
                                           max_depth=max_depth, differences=mode == "forward")
            return float(np.sum(d.numpy().astype(np.float64) * weights_np))
        if mode == "replay":
            _, g = compiled.render_backward(camera, weights_np, [name], spp=spp, seed=seed,
                                            max_depth=max_depth)
            return float(np.dot(g[name], direction))
        value = mi.Float(np.asarray(x0, np.float32))
        dr.enable_grad(value)
        compiled.set(name, value)
        if full:
            image = compiled.render(camera, spp=spp, seed=seed, max_depth=max_depth)
        else:
            moving = compiled.moving_meshes() if edges else []
            image = tracer.render(compiled.mitsuba_scene, compiled.environment, camera, spp, seed,
                                  moving=moving)
        dr.backward(dr.sum(image * weights, axis=None), flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
        return float(np.dot(np.array(dr.grad(value)), direction))

    ad = [derivative(s) for s in range(seeds)]
    fd = [(primal(x0 + h * direction, s) - primal(x0 - h * direction, s)) / (2 * h)
          for s in range(seeds)]
    compiled.set(name, x0)
    se = lambda v: float(np.std(v, ddof=1) / np.sqrt(len(v)))  # noqa: E731
    return float(np.mean(ad)), se(ad), float(np.mean(fd)), se(fd)


def assert_gradients_agree(ad, ad_se, fd, fd_se, rel=0.05, sigmas=4.0):
    assert abs(fd) > sigmas * fd_se, f"FD {fd:.4g} +- {fd_se:.3g} is not clearly nonzero"
    tol = sigmas * np.hypot(ad_se, fd_se) + rel * abs(fd)
    assert abs(ad - fd) <= tol, f"AD {ad:.5g} +- {ad_se:.3g} vs FD {fd:.5g} +- {fd_se:.3g} (tol {tol:.3g})"
