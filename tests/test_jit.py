"""Kernels are compiled once: renders at new parameter values reuse them.

Dr.Jit compiles a kernel for every distinct trace. Values that change between renders (parameter
values, poses, silhouette samples drawn in NumPy) must enter kernels as memory of a fixed alignment
rather than as literals or as NumPy memory of whatever alignment it happened to get, or each
render compiles afresh (measured on the diagnosis suite's pose fit: 3 s of compilation per render,
97 % of its time).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, compile_scene
from abs.render.jit import from_numpy
from abs.scene import load_scene


def _kernel_hashes(run) -> set[str]:
    dr.kernel_history()  # clear
    run()
    return {k["hash"] for k in dr.kernel_history() if "hash" in k}


def test_from_numpy_is_aligned_copy():
    x = np.arange(7, dtype=np.float64)
    y = from_numpy(mi.Float, x)
    x[0] = 99.0  # a copy: the NumPy array may change or die afterwards
    assert np.array_equal(np.asarray(y), np.arange(7, dtype=np.float32))


def test_pose_gradient_renders_reuse_kernels(silhouette_scene_dir):
    compiled = compile_scene(load_scene(silhouette_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.35]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(16, 16, np.radians(25)), R, t, 16, 16)

    def attached_render(pose, tangent):
        value = from_numpy(mi.Float, pose)
        dr.enable_grad(value)
        compiled.set("sphere.pose", value)
        image = compiled.render(camera, spp=2, seed=1)
        dr.set_grad(value, from_numpy(mi.Float, tangent))
        dr.forward_to(image)
        return dr.grad(image).numpy()

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first = _kernel_hashes(lambda: attached_render([0, 0, 0, 0, 0, 0], np.eye(6)[0]))
        # A new pose moves the silhouette (new NumPy edge samples) and a new tangent: same kernels.
        second = _kernel_hashes(lambda: attached_render([0.002, -0.001, 0, 0, 0.05, 0], np.eye(6)[1]))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert first and second <= first, f"{len(second - first)} kernels compiled anew"


def test_large_seeds_are_wrapped_for_batched_renders(silhouette_scene_dir, monkeypatch):
    # A batched render derives its seeds as seed x 7919 + batch; for call seeds above ~540 000
    # that exceeds the 32 bits a Mitsuba sampler takes (it raised a TypeError).
    import abs.render.compiled as compiled_module

    compiled = compile_scene(load_scene(silhouette_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.35]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(16, 16, np.radians(25)), R, t, 16, 16)
    monkeypatch.setattr(compiled_module, "MAX_SAMPLES_IN_FLIGHT", 16 * 16 * 2)  # 2 spp per batch
    big = compiled.render(camera, spp=4, seed=10**6).numpy()
    other = compiled.render(camera, spp=4, seed=10**6 + 1).numpy()
    assert np.isfinite(big).all() and big.mean() > 0
    assert not np.array_equal(big, other)  # distinct seeds stay distinct after wrapping
