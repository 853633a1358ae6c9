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
import pytest

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
    compiled = compile_scene(load_scene(silhouette_scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.35]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(16, 16, np.radians(25)), R, t, 16, 16)
    monkeypatch.setenv("ABS_SAMPLES_IN_FLIGHT", str(16 * 16 * 2))  # 2 spp per batch
    big = compiled.render(camera, spp=4, seed=10**6).numpy()
    other = compiled.render(camera, spp=4, seed=10**6 + 1).numpy()
    assert np.isfinite(big).all() and big.mean() > 0
    assert not np.array_equal(big, other)  # distinct seeds stay distinct after wrapping


def _default_views(compiled, width: int, height: int, count: int):
    from abs.simulate import place_cameras

    return [Camera(v["K"], v["R"], v["t"], width, height) for v in place_cameras(compiled, count, width, height)]


def test_views_spp_values_and_channels_reuse_kernels():
    """The default scene (dispersive glass): a second view, another resolution, spp and seed, new
    parameter values and a tangent on another colour channel compile nothing new, in primal and
    forward-mode renders and in path replay."""
    from pathlib import Path

    compiled = compile_scene(load_scene(Path(__file__).resolve().parents[1] / "scenes/default/scene.toml"))
    first_view, second_view = _default_views(compiled, 20, 15, 2)
    other_size = _default_views(compiled, 28, 21, 1)[0]
    weights = np.ones((15, 20, 3))

    def run(camera, spp, seed, channel, absorption, ior):
        compiled.set("glass.absorption", absorption)
        compiled.set("glass.ior", ior)
        compiled.render(camera, spp=spp, seed=seed).numpy()
        tangent = np.eye(3)[channel]
        compiled.render_forward(camera, {"glass.ior": tangent, "glass.absorption": tangent},
                                spp=spp, seed=seed)
        if camera.width == 20:
            compiled.render_backward(camera, weights, ["glass.absorption", "environment.scale"],
                                     spp=spp, seed=seed)

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first = _kernel_hashes(lambda: run(first_view, 2, 0, 0, [4.0, 1.5, 2.5], [1.515, 1.52, 1.53]))
        second = _kernel_hashes(lambda: (run(second_view, 3, 5, 2, [3.0, 2.0, 1.0], [1.50, 1.51, 1.52]),
                                         run(other_size, 1, 7, 1, [3.0, 2.0, 1.0], [1.50, 1.51, 1.52])))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert first and second <= first, f"{len(second - first)} kernels compiled anew"


def test_brdf_pca_renders_reuse_kernels(silhouette_scene_dir, tmp_path):
    from abs.brdf.basis import BRDFBasis
    from abs.io.merl import MERL_SIZE

    rng = np.random.default_rng(0)
    BRDFBasis(mean=np.zeros(MERL_SIZE, np.float32),
              components=(rng.normal(size=(2, MERL_SIZE)) * 0.3).astype(np.float32),
              median=np.full(MERL_SIZE, 0.2, np.float32), epsilon=1e-3).save(tmp_path / "basis.npz")
    for asset in ("sphere.ply", "env.exr"):
        (tmp_path / asset).write_bytes((silhouette_scene_dir / asset).read_bytes())
    (tmp_path / "scene.toml").write_text(
        '[environment]\nfile = "env.exr"\n\n[materials.paint]\ntype = "brdf_pca"\nbasis = "basis.npz"\n'
        'coefficients = [0.5, -0.3]\n\n[[objects]]\nname = "sphere"\nmesh = "sphere.ply"\nmaterial = "paint"\n')
    compiled = compile_scene(load_scene(tmp_path / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.05, 0.3]), np.array([0.0, 0.05, 0.0]))
    camera = Camera(intrinsics_from_fov(16, 16, np.radians(25)), R, t, 16, 16)

    def run(coefficients, spp, seed):
        compiled.set("paint.coefficients", coefficients)
        compiled.render(camera, spp=spp, seed=seed).numpy()
        compiled.render_forward(camera, {"paint.coefficients": [1.0, 0.0]}, spp=spp, seed=seed)

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first = _kernel_hashes(lambda: run([0.5, -0.3], 2, 0))
        second = _kernel_hashes(lambda: run([0.1, 0.4], 4, 3))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert first and second <= first, f"{len(second - first)} kernels compiled anew"


def _small_view(scene_dir):
    """The small glass scene compiled, and a 16x12 view of it."""
    compiled = compile_scene(load_scene(scene_dir / "scene.toml"))
    R, t = look_at(np.array([0.0, 0.08, 0.32]), np.array([0.0, 0.05, 0.0]))
    return compiled, Camera(intrinsics_from_fov(16, 12, np.radians(30)), R, t, 16, 12)


def test_derivative_renders_bound_the_samples_in_flight(small_scene_dir, monkeypatch):
    """Forward mode and path replay keep no recorded graph: their memory is the path loop's state
    for the samples in flight, which CompiledScene bounds whatever the spp."""
    compiled, camera = _small_view(small_scene_dir)
    cap = 16 * 12 * 2
    monkeypatch.setenv("ABS_SAMPLES_IN_FLIGHT", str(cap))
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        compiled.render_forward(camera, {"glass.absorption": [1.0, 0.0, 0.0]}, spp=16, seed=1)
        compiled.render_backward(camera, np.ones((12, 16, 3)), ["glass.absorption"], spp=16, seed=1)
        # The path-tracing kernels (thousands of operations; the small ones write films and
        # scene buffers, sized by the image and the scene).
        sizes = [k["size"] for k in dr.kernel_history() if k.get("operation_count", 0) > 500]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert sizes and max(sizes) <= cap, max(sizes)


def test_samples_in_flight_follows_the_backend_and_the_override(monkeypatch):
    from abs.render.compiled import SAMPLES_IN_FLIGHT, samples_in_flight

    monkeypatch.delenv("ABS_SAMPLES_IN_FLIGHT", raising=False)
    backend = "cuda" if mi.variant().startswith("cuda") else "llvm"
    assert samples_in_flight() == SAMPLES_IN_FLIGHT[backend]
    monkeypatch.setenv("ABS_SAMPLES_IN_FLIGHT", "4096")
    assert samples_in_flight() == 4096
    for bad in ("0", "-3", "many"):
        monkeypatch.setenv("ABS_SAMPLES_IN_FLIGHT", bad)
        with pytest.raises(ValueError, match="ABS_SAMPLES_IN_FLIGHT"):
            samples_in_flight()


def test_batched_gradient_with_a_linear_sensor_renders_no_extra_image(small_scene_dir, monkeypatch):
    """A linear sensor's adjoint is the same at every image, so a batched gradient takes the image
    from its batches' own primal renders: the same image and gradient as when it first renders
    the whole image (the path a non-linear sensor needs), with one path-tracing pass fewer per
    batch."""
    import abs.render.sensor as sensor_module

    compiled, camera = _small_view(small_scene_dir)
    monkeypatch.setenv("ABS_SAMPLES_IN_FLIGHT", str(16 * 12 * 2))  # 2 spp per batch
    weight = np.random.default_rng(3).uniform(-1.0, 1.0, (12, 16, 3))
    names = ["glass.absorption", "environment.scale"]
    assert compiled.sensor.is_linear()

    def traced(fn):
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            dr.kernel_history()
            out = fn()
            passes = sum(1 for k in dr.kernel_history() if k.get("operation_count", 0) > 500)
        finally:
            dr.set_flag(dr.JitFlag.KernelHistory, False)
        return out, passes

    (image, gradient), fast = traced(lambda: compiled.render_backward(camera, weight, names, spp=8, seed=2))
    monkeypatch.setattr(sensor_module.Sensor, "is_linear", lambda self: False)
    (image_ref, gradient_ref), slow = traced(lambda: compiled.render_backward(camera, weight, names, spp=8, seed=2))
    np.testing.assert_array_equal(image, image_ref)
    np.testing.assert_array_equal(image, compiled.render(camera, spp=8, seed=2).numpy())
    for name in names:
        np.testing.assert_allclose(gradient[name], gradient_ref[name], rtol=1e-5)
        assert np.all(gradient[name] != 0.0)
    assert fast < slow, (fast, slow)


def test_a_sensor_is_linear_only_at_unit_response_and_without_its_own_gradients():
    from abs.render.sensor import Sensor

    assert Sensor([0.1, 0.0], [1.0, 1.0, 1.0], [0.01, 0.0, 0.0], np.eye(3).ravel() * 1.1).is_linear()
    assert not Sensor([0.0, 0.0], [1.0, 0.9, 1.0], [0.0] * 3).is_linear()
    for field in ("vignetting", "stray_light", "colour_matrix", "intrinsics_offset"):
        sensor = Sensor([0.0, 0.0], [1.0, 1.0, 1.0], [0.0] * 3)
        dr.enable_grad(getattr(sensor, field))
        assert not sensor.is_linear(), field
