"""Path-length recordings: one render gives the image at every absorption and environment scale.

A render's paths do not depend on the absorption at all (it only scales what they carry, and
Russian roulette's decisions follow a throughput without the glass's weights), so a render at
absorption ``sigma`` and a recording reweighted to ``sigma``, both with the same seed, must agree
up to the binning's interpolation error, with roulette or without.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.render import Camera, compile_scene
from abs.render.integrator import PathTracer
from abs.render.path_lengths import (JOINT_NODES, PathLengthRecording, bin_light, length_bins,
                                     reweight)
from abs.scene import load_scene
from conftest import sphere_in_view

W, H, SPP = 24, 18, 16
RECORDED = np.array([2.0, 2.0, 2.0])  # 1/m


@pytest.fixture(scope="module")
def scene(small_scene_dir):
    return sphere_in_view(small_scene_dir, W, H)


def _glass(compiled):
    return next(s.bsdf() for s in compiled.mitsuba_scene.shapes() if s.bsdf().id() == "glass")


@pytest.mark.parametrize("factor", [0.0, 1.0, 5.0, 10.0])
@pytest.mark.parametrize("rr_depth", [8, 2])
def test_reweighting_equals_a_render(scene, factor, rr_depth):
    """Sample by sample, without roulette (``rr_depth`` 8 = the path length) and with roulette from
    the second vertex on: its decisions must not depend on the absorption (with the glass's
    absorption in roulette's throughput, the sampling benchmark's render and reweighted recording
    differed by 3e-3 RMS, a tenth of the residual)."""
    compiled, camera = scene
    before = compiled.get("glass.absorption")
    tracer = PathTracer(max_depth=8, rr_depth=rr_depth)
    bins = length_bins(0.173)  # the 10 cm sphere's bounding-box diagonal
    try:
        compiled.set("glass.absorption", RECORDED)
        histogram = tracer.record(compiled.mitsuba_scene, compiled.environment, camera, SPP, 3,
                                  [_glass(compiled)], [bins])
        recording = PathLengthRecording(histogram.numpy().reshape(H, W, 3, -1), (bins,), ("glass",),
                                        RECORDED[None], 1.0, SPP, 3)
        sigma = factor * RECORDED * np.array([1.0, 1.5, 0.5])
        compiled.set("glass.absorption", sigma)
        with dr.suspend_grad():
            direct = tracer.render(compiled.mitsuba_scene, compiled.environment, camera, SPP, 3).numpy()
        reweighted = reweight(recording, sigma, 1.0)[0]
    finally:
        compiled.set("glass.absorption", before)
    # Linear interpolation of exp(-d sigma L) between nodes: relative error <= (d sigma h)^2 / 8.
    bound = (np.max(np.abs(sigma - RECORDED)) * bins.spacing) ** 2 / 8
    np.testing.assert_allclose(reweighted, direct, rtol=1.5 * bound + 1e-5, atol=1e-6)
    if factor != 1.0:  # the glass's pixels did change: the check compares something
        assert np.max(np.abs(direct - reweight(recording, RECORDED, 1.0)[0])) > 0.01


def test_reweighting_with_roulette_is_unbiased(scene):
    """Reweighted and direct renders with other seeds agree in expectation (the reweighting
    is unbiased, not just equal to one render)."""
    compiled, camera = scene
    before = compiled.get("glass.absorption")
    recording = compiled.record(camera, spp=64, seed=1)  # at absorption 0
    try:
        sigma = np.array([20.0, 5.0, 40.0])
        compiled.set("glass.absorption", sigma)
        reweighted = compiled.render_recorded(recording, camera).numpy()
        direct = np.stack([compiled.render(camera, spp=64, seed=10 + k).numpy() for k in range(4)])
        clear = reweight(recording, np.zeros(3), 1.0)[0]
    finally:
        compiled.set("glass.absorption", before)
    glass = np.abs(clear - reweighted).sum(axis=-1) > 0.02  # pixels the absorption darkens
    assert glass.sum() > 20
    difference = reweighted[glass] - direct.mean(axis=0)[glass]
    spread = np.std(direct[:, glass], axis=0, ddof=1)
    standard_error = np.sqrt(np.sum(spread ** 2 * (1 + 1 / 4), axis=0)) / glass.sum()
    z = np.mean(difference, axis=0) / standard_error
    assert np.all(np.abs(z) < 4), z
    # What the test guards against: light left at zero length is far off (darkening missed).
    assert np.all(np.abs(np.mean(clear[glass] - direct.mean(axis=0)[glass], axis=0))
                  > 8 * standard_error)


def test_same_samples_as_a_render_at_the_recording_absorption(scene):
    compiled, camera = scene
    recording = compiled.record(camera, spp=SPP, seed=5, absorption_per_m=compiled.get("glass.absorption"))
    direct = compiled.render(camera, spp=SPP, seed=5).numpy()
    np.testing.assert_allclose(compiled.render_recorded(recording, camera).numpy(), direct,
                               rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name, tangent", [("glass.absorption", [1.0, 0.0, 0.0]),
                                           ("glass.absorption", [0.0, 0.0, 1.0]),
                                           ("environment.scale", [1.0]),
                                           ("sensor.stray_light", [0.0, 1.0, 0.0])])
def test_closed_form_derivative_matches_finite_differences(scene, name, tangent):
    compiled, camera = scene
    recording = compiled.record(camera, spp=SPP, seed=2)
    x0 = compiled.get(name)
    image, derivative = compiled.render_recorded_forward(recording, camera, {name: tangent})
    h = 1e-2 * max(1.0, float(np.max(np.abs(x0))))
    try:
        compiled.set(name, x0 + h * np.asarray(tangent))
        upper = compiled.render_recorded(recording, camera).numpy().astype(np.float64)
        compiled.set(name, x0 - h * np.asarray(tangent))
        lower = compiled.render_recorded(recording, camera).numpy().astype(np.float64)
    finally:
        compiled.set(name, x0)
    difference = (upper - lower) / (2 * h)
    assert np.max(np.abs(difference)) > 1e-3
    np.testing.assert_allclose(derivative.numpy(), difference, rtol=2e-2, atol=2e-4 * np.max(np.abs(difference)))
    np.testing.assert_allclose(image.numpy(), compiled.render_recorded(recording, camera).numpy())


def test_absorption_derivative_matches_forward_mode_without_roulette(scene):
    """The closed form ``-sum f L exp(-sigma L)`` against the renderer's own forward mode."""
    compiled, camera = scene
    tracer = PathTracer(max_depth=8, rr_depth=8)
    glass = _glass(compiled)
    bins = length_bins(0.173)
    sigma = compiled.get("glass.absorption")
    histogram = tracer.record(compiled.mitsuba_scene, compiled.environment, camera, SPP, 4, [glass], [bins])
    recording = PathLengthRecording(histogram.numpy().reshape(H, W, 3, -1), (bins,), ("glass",),
                                    sigma[None], 1.0, SPP, 4)
    _, closed = compiled.render_recorded_forward(recording, camera, {"glass.absorption": [1.0, 1.0, 1.0]})
    compiled._push_tangents({"glass.absorption": [1.0, 1.0, 1.0]})
    try:
        _, forward = tracer.render_forward(compiled.mitsuba_scene, compiled.environment, camera, SPP, 4)
    finally:
        compiled.set("glass.absorption", sigma)
    closed = closed.numpy()
    assert np.min(closed) < -1e-3
    np.testing.assert_allclose(closed, forward.numpy(), rtol=1e-2, atol=1e-5)


def test_recording_refuses_parameters_that_move_paths(scene):
    compiled, camera = scene
    recording = compiled.record(camera, spp=1)
    with pytest.raises(ValueError, match="glass.ior change the light paths"):
        compiled.render_recorded_forward(recording, camera, {"glass.ior": [1.0, 1.0, 1.0]})
    assert compiled.needs_render(["glass.absorption", "environment.scale", "sensor.response",
                                  "glass.ior"], ("glass",)) == ["glass.ior"]


@pytest.fixture(scope="module")
def two_glasses(tmp_path_factory):
    """The small scene with a second glass sphere of another material (``tint``) beside the
    first, and a camera that sees light pass through both (through one, then the other)."""
    from conftest import (make_backdrop, make_checker, make_env, make_sphere_and_floor,
                          sphere_scene_toml, with_second_glass)

    root = tmp_path_factory.mktemp("two_glasses")
    make_sphere_and_floor(root)
    make_backdrop(root)
    make_env(root / "env.exr")
    make_checker(root / "checker.png")
    text = sphere_scene_toml(["glass.absorption"], absorption=[3.0, 3.0, 3.0])
    (root / "scene.toml").write_text(with_second_glass(text))
    compiled = compile_scene(load_scene(root / "scene.toml"))
    R, t = look_at(np.array([0.2, 0.08, 0.3]), np.array([0.03, 0.05, -0.02]))
    return compiled, Camera(intrinsics_from_fov(W, H, np.radians(40)), R, t, W, H)


@pytest.mark.parametrize("sigma_glass, sigma_tint", [((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
                                                     ((5.0, 1.0, 8.0), (2.0, 6.0, 10.0)),
                                                     ((10.0, 10.0, 0.0), (0.0, 12.0, 4.0))])
def test_two_glasses_reweight_jointly_to_a_render(two_glasses, sigma_glass, sigma_tint):
    """One recording of both glasses' lengths gives the render at any pair of absorptions (one
    path through both carries exp(-s1 L1 - s2 L2), which separate histograms could not give), up
    to the joint nodes' interpolation error; and its closed-form derivatives match differences."""
    compiled, camera = two_glasses
    names = ("glass.absorption", "tint.absorption")
    before = [compiled.get(n) for n in names]
    recording = compiled.record(camera, spp=SPP, seed=7, materials=("glass", "tint"))
    assert recording.histogram.shape == (H, W, 3, (JOINT_NODES + 2) ** 2)
    try:
        for name, value in zip(names, (sigma_glass, sigma_tint)):
            compiled.set(name, np.asarray(value, np.float64))
        direct = compiled.render(camera, spp=SPP, seed=7).numpy()
        reweighted = compiled.render_recorded(recording, camera).numpy()
        # Derivatives one per metre above (absorption is bounded below by 0).
        for name, value in zip(names, (sigma_glass, sigma_tint)):
            compiled.set(name, np.asarray(value, np.float64) + 1.0)
        both = [0.5, -0.25, 1.0], [1.0, 0.5, -0.5]
        _, derivative = compiled.render_recorded_forward(recording, camera, dict(zip(names, both)))
        h = 0.05  # the histogram is float32: smaller steps difference its rounding
        moved = []
        for sign in (1, -1):
            for name, value, tangent in zip(names, (sigma_glass, sigma_tint), both):
                compiled.set(name, np.asarray(value, np.float64) + 1.0 + sign * h * np.asarray(tangent))
            moved.append(compiled.render_recorded(recording, camera).numpy())
    finally:
        for name, value in zip(names, before):
            compiled.set(name, value)
    change = max(np.max(np.abs(np.subtract(sigma_glass, 0))), np.max(np.abs(np.subtract(sigma_tint, 0))))
    spacing = max(b.spacing for b in recording.bins)
    bound = 2 * (change * spacing) ** 2 / 8  # each length's tent interpolation, two lengths
    np.testing.assert_allclose(reweighted, direct, rtol=1.5 * bound + 1e-5, atol=1e-6)
    difference = (moved[0] - moved[1]) / (2 * h)
    np.testing.assert_allclose(derivative.numpy(), difference, rtol=1e-3,
                               atol=1e-4 * np.max(np.abs(difference)))
    if change > 0:  # both glasses' pixels changed: the check compares something
        clear = compiled.render_recorded(recording, camera).numpy()
        assert np.max(np.abs(direct - clear)) > 0.01


def test_a_path_through_both_glasses_is_seen(two_glasses):
    """The camera of the two-glass tests sees light that crossed both glasses: reweighting one
    glass's absorption and then the other's is not the sum of their separate effects."""
    compiled, camera = two_glasses
    recording = compiled.record(camera, spp=SPP, seed=7, materials=("glass", "tint"))
    before = [compiled.get("glass.absorption"), compiled.get("tint.absorption")]
    try:
        images = {}
        for a in (0.0, 20.0):
            for b in (0.0, 20.0):
                compiled.set("glass.absorption", np.full(3, a))
                compiled.set("tint.absorption", np.full(3, b))
                images[a, b] = compiled.render_recorded(recording, camera).numpy()
    finally:
        compiled.set("glass.absorption", before[0])
        compiled.set("tint.absorption", before[1])
    interaction = images[20.0, 20.0] - images[20.0, 0.0] - images[0.0, 20.0] + images[0.0, 0.0]
    assert np.max(np.abs(interaction)) > 1e-3


def test_joint_binning_of_known_paths_including_overflow():
    """Paths of known light and lengths in two materials, some beyond the last node of either:
    the binned recording reweights to the exact sum of ``f exp(-s1 L1 - s2 L2)`` within the
    interpolation bound where no length overflows, within 2 % where some do (an overflow is
    reweighted at its mean length), and its derivatives match differences of itself."""
    rng = np.random.default_rng(3)
    bins = (length_bins(0.1, 8), length_bins(0.05, 6))
    ranges = [b.spacing * (b.n_nodes - 1) for b in bins]
    n = 400
    lengths = [rng.uniform(0, 1.3 * r, n) for r in ranges]
    light = rng.uniform(0.0, 1.0, (n, 3))
    histogram = dr.zeros(mi.Float, 3 * bins[0].slots * bins[1].slots)
    bin_light(histogram, mi.UInt32(np.zeros(n, np.uint32)), mi.Color3f(light.T),
              [mi.Float(l) for l in lengths], bins)
    recording = PathLengthRecording(histogram.numpy().reshape(1, 1, 3, -1), bins, ("a", "b"),
                                    np.zeros((2, 3)), 1.0, 1, 0)
    sigma = np.array([[2.0, 4.0, 8.0], [6.0, 1.0, 3.0]])
    exact = (light * np.exp(-np.outer(lengths[0], sigma[0]) - np.outer(lengths[1], sigma[1]))).sum(0)
    image = reweight(recording, sigma, 1.0)[0][0, 0]
    np.testing.assert_allclose(image, exact, rtol=0.02)
    inside = (lengths[0] < ranges[0]) & (lengths[1] < ranges[1])
    kept = light * inside[:, None]
    histogram = dr.zeros(mi.Float, 3 * bins[0].slots * bins[1].slots)
    bin_light(histogram, mi.UInt32(np.zeros(n, np.uint32)), mi.Color3f(kept.T),
              [mi.Float(l) for l in lengths], bins)
    inner = PathLengthRecording(histogram.numpy().reshape(1, 1, 3, -1), bins, ("a", "b"),
                                np.zeros((2, 3)), 1.0, 1, 0)
    exact_inner = (kept * np.exp(-np.outer(lengths[0], sigma[0]) - np.outer(lengths[1], sigma[1]))).sum(0)
    bound = sum((np.max(sigma[m]) * bins[m].spacing) ** 2 / 8 for m in range(2))
    np.testing.assert_allclose(reweight(inner, sigma, 1.0)[0][0, 0], exact_inner, rtol=bound + 1e-5)
    tangent = np.array([[1.0, -0.5, 0.25], [0.5, 1.0, -1.0]])
    derivative = reweight(recording, sigma, 1.0, d_absorption=tangent)[1][0, 0]
    h = 1e-4
    difference = (reweight(recording, sigma + h * tangent, 1.0)[0]
                  - reweight(recording, sigma - h * tangent, 1.0)[0])[0, 0] / (2 * h)
    # Exact for each material's own overflow; across materials the overflow's mean is held.
    np.testing.assert_allclose(derivative, difference, rtol=0.02)


def test_evenly_spread_lengths_reweight_without_the_interpolation_bias():
    """Tent binning interpolates exp(-sigma L) linearly between nodes, which overestimates it by
    b^2 / 12 on average over light spread evenly between two nodes (b = sigma * spacing); the
    nodes' weights divide that out. Light in glass beyond the first node (whose node 0 also holds
    the light that never entered glass, and is left alone) reweights to the exact sum within a
    twentieth of that bias; without the weights the error is the bias, up to 6 %."""
    rng = np.random.default_rng(5)
    bins = length_bins(0.1, 8)
    n = 200_000
    lengths = rng.uniform(bins.spacing, bins.spacing * (bins.n_nodes - 1), n)
    light = rng.uniform(0.5, 1.0, (n, 3))
    histogram = dr.zeros(mi.Float, 3 * bins.slots)
    bin_light(histogram, mi.UInt32(np.zeros(n, np.uint32)), mi.Color3f(light.T), [mi.Float(lengths)],
              (bins,))
    recording = PathLengthRecording(histogram.numpy().reshape(1, 1, 3, -1), (bins,), ("glass",),
                                    np.zeros((1, 3)), 1.0, 1, 0)
    sigma = np.array([4.0, 8.0, 16.0])
    exact = (light * np.exp(-np.outer(lengths, sigma))).sum(0)
    image, derivative = reweight(recording, sigma, 1.0, d_absorption=np.ones(3))
    bias = (sigma * bins.spacing) ** 2 / 12
    assert np.all(bias > 3e-3)  # the uncorrected error would be seen
    np.testing.assert_array_less(np.abs(image[0, 0] / exact - 1.0), bias / 20)
    d_exact = -(light * lengths[:, None] * np.exp(-np.outer(lengths, sigma))).sum(0)
    np.testing.assert_array_less(np.abs(derivative[0, 0] / d_exact - 1.0), bias / 5)
