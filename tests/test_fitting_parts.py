"""The pieces of a fit: transforms, the optimisers, Laplace, downsampling, Jacobians."""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs.errors import InputError
from abs.fitting.laplace import laplace, with_monte_carlo_error
from abs.fitting.optimisers import OptimizerState
from abs.fitting.optimisers.adam import adam
from abs.fitting.optimisers.lm import cross_curvature, gauss_newton_refinement, levenberg_marquardt
from abs.fitting.settings import parse_schedule, schedule_value
from abs.model import ParameterVector, estimate_image_noise
from abs.model.downsampling import downsample, downsample_camera
from abs.runs.files import load_checkpoint, save_checkpoint
from abs.params.names import Parameter


def _vector():
    specs = {
        "glass.ior": Parameter("glass.ior", 3, "1", 1.0, 3.0, None),
        "glass.absorption": Parameter("glass.absorption", 3, "1/m", 0.0, np.inf, None),
        "obj.pose": Parameter("obj.pose", 6, "m, m, m, rad, rad, rad", -np.inf, np.inf, None),
    }
    initial = {"glass.ior": [1.5, 1.52, 1.55], "glass.absorption": [0.0, 2.0, 8.0],
               "obj.pose": [0.0] * 6}
    return ParameterVector.build(specs, list(specs), initial)


def test_transforms_round_trip_stay_in_bounds_and_have_the_right_derivative():
    v = _vector()
    z = v.to_unconstrained(v.initial)
    assert np.allclose(v.to_physical(z), v.initial)
    assert v.initial[3] > 0  # a start on the bound is moved inside
    extreme = v.to_physical(np.full(v.size, -50.0))
    assert np.all(extreme[:3] >= 1.0) and np.all(extreme[3:6] >= 0.0)
    h = 1e-6
    fd = (v.to_physical(z + h) - v.to_physical(z - h)) / (2 * h)
    assert np.allclose(v.derivative(z), fd, rtol=1e-5, atol=1e-9)
    assert np.allclose(v.step[6:], [0.01] * 3 + [0.05] * 3)  # pose: cm and a few degrees
    assert v.labels()[0] == "glass.ior[0]" and len(v.labels()) == 12


def _linear_problem(seed=0, m=200, noise=0.1):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, 3))
    truth = np.array([1.0, -2.0, 0.5])
    y = A @ truth + noise * rng.normal(size=m)
    return A, y, truth


def test_levenberg_marquardt_solves_least_squares():
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    seen = []
    same = lambda z, it: ((A @ z - y, A), (A @ z - y, A), 0.0)  # noqa: E731  (noise-free renders)
    state = levenberg_marquardt(same, OptimizerState("lm", 0, np.zeros(3)), 20,
                                on_iteration=lambda s: seen.append(s.iteration))
    assert np.allclose(state.z, exact, atol=1e-6)
    assert state.solver.converged
    assert seen == list(range(1, len(seen) + 1)) and len(seen) < 20


def test_levenberg_marquardt_treats_a_non_finite_trial_as_a_failed_step():
    """A trial point whose renders are not finite (NaN) is rejected and the damping grows; the
    fit still reaches the solution, which lies where the renders are finite."""
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]

    def evaluate(z, it):
        r = A @ z - y
        if it == 2:  # the first trial step renders NaN
            r = np.full_like(r, np.nan)
        return (r, A), (r, A), 0.0

    state = levenberg_marquardt(evaluate, OptimizerState("lm", 0, np.zeros(3)), 30)
    assert np.allclose(state.z, exact, atol=1e-6)
    assert [h.get("non_finite", False) for h in state.history][:2] == [False, True]


def test_levenberg_marquardt_has_no_bias_from_noise_that_depends_on_the_parameters():
    """Renders whose Monte-Carlo noise grows with the parameter (a brighter glass is noisier):
    least squares on one fixed-seed render prefers the darker, less noisy value; the two-seed
    objective's minimum is the truth's."""
    rng = np.random.default_rng(3)
    a = rng.uniform(0.5, 1.5, 4000)
    truth = 2.0
    y = truth * a + 0.01 * rng.normal(size=a.size)
    noise = rng.normal(size=(2, a.size))  # two fixed seeds: relative noise of 100 %

    def render(z, k):
        return z[0] * a * (1 + noise[k]) - y, (a * (1 + noise[k]))[:, None]

    one_seed = levenberg_marquardt(lambda z, it: (render(z, 0), render(z, 0), 0.0),
                                   OptimizerState("lm", 0, np.array([1.0])), 30)
    two_seed = levenberg_marquardt(lambda z, it: (render(z, 0), render(z, 1), 0.0),
                                   OptimizerState("lm", 0, np.array([1.0])), 30)
    assert one_seed.z[0] < 0.6 * truth  # the biased minimum: truth / (1 + variance)
    assert abs(two_seed.z[0] - truth) < 0.05 * truth, two_seed.z


def test_levenberg_marquardt_reports_errors_of_the_evaluation():
    def failing(z, it):
        raise RuntimeError("renderer failed")

    with pytest.raises(RuntimeError, match="renderer failed"):
        levenberg_marquardt(failing, OptimizerState("lm", 0, np.zeros(2)), 3)


def test_refinement_takes_full_steps_despite_very_noisy_jacobians():
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    rng = np.random.default_rng(1)
    noise = np.abs(A).mean()  # Jacobian noise as large as its signal (glass at low spp)

    def noisy(z, it):  # unbiased, independent Jacobians, as from independent renders
        return A @ z - y, tuple(A + noise * rng.normal(size=A.shape) for _ in range(2)), 0.0

    start = exact + 0.3
    state = gauss_newton_refinement(noisy, OptimizerState("lm", 0, start), steps=8)
    assert np.allclose(state.z, exact, atol=0.03)
    # One Gauss-Newton step from J1^T J1 would stop about halfway (curvature inflated by the
    # noise): the cross curvature's first step removes most of the offset.
    first = np.asarray(state.solver.refinement.points[0])
    assert np.all(np.abs(first - exact) < 0.1 * 0.3), first - exact


def test_refinement_travels_far_when_the_solution_is_many_typical_steps_away():
    """Levenberg-Marquardt's fixed-seed optimum can sit many typical steps from the unbiased one
    (a BRDF whose specular lobe changes the render variance: measured 3 typical steps). Clipped
    steps that keep pointing the same way widen the trust radius; points reached while still
    clipped are not averaged."""
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    rng = np.random.default_rng(2)
    noise = 0.3 * np.abs(A).mean()

    def noisy(z, it):
        return A @ z - y, tuple(A + noise * rng.normal(size=A.shape) for _ in range(2)), 0.0

    start = exact + np.array([6.0, -4.0, 5.0])
    state = gauss_newton_refinement(noisy, OptimizerState("lm", 0, start), steps=6)
    assert np.allclose(state.z, exact, atol=0.05), state.z - exact
    # Points reached while still travelling (clipped, or before every coordinate turned back)
    # are flagged, and not averaged.
    clipped = state.solver.refinement.clipped
    assert clipped[0] and clipped[1]
    points = np.asarray([start, *state.solver.refinement.points])
    assert np.abs(np.diff(points, axis=0)).max() >= 2.0  # the radius grew
    # A fixed radius of one typical step would still be 2 away after 4 steps.
    fixed = gauss_newton_refinement(noisy, OptimizerState("lm", 0, start), steps=4, max_step=1.0)
    assert np.abs(np.asarray(fixed.solver.refinement.points[0]) - start).max() == pytest.approx(1.0)


def test_refinement_averages_points_that_scatter_beyond_the_trust_radius():
    """At the solution, full Newton steps on fresh renders scatter by more than the trust radius
    (glass at 64 spp): those clipped steps turn back and are averaged, not taken for travel."""
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    rng = np.random.default_rng(5)
    scatter = 1.5  # typical steps per Newton step
    noise = scatter * np.linalg.norm(A, axis=0).mean()

    def noisy(z, it):
        return A @ z - y + noise * rng.normal(size=len(y)), (A, A), 0.0

    state = gauss_newton_refinement(noisy, OptimizerState("lm", 0, exact.copy()), steps=24)
    averaged = len(state.solver.refinement.points) - sum(state.solver.refinement.clipped)
    assert averaged >= 12, state.solver.refinement.clipped
    assert np.all(np.abs(state.z - exact) < 1.0), state.z - exact


def _rare_jumps_problem():
    """A linear model whose weak column's Jacobian noise is rare large jumps: the least-squares
    solution, and ``noisy_for(seed)``, an evaluation with fresh noise at every call (column 0:
    jumps of sd 1.3 in 20 of 400 pixels, noise energy 34 against a signal energy of 4)."""
    A = np.random.default_rng(0).normal(size=(400, 3))
    A[:, 0] *= 0.1
    y = A @ np.array([0.5, -1.0, 2.0])

    def noisy_for(seed):
        rng = np.random.default_rng(seed)

        def noisy(z, it):
            J = [A.copy(), A.copy()]
            for j in J:
                j[:20, 0] += 1.3 * rng.normal(size=20)
            return A @ z - y + 0.2 * rng.normal(size=400), tuple(J), 0.0

        return noisy

    return np.linalg.lstsq(A, y, rcond=None)[0], noisy_for


def test_refinement_pools_the_curvature_of_a_column_whose_noise_is_rare_large_jumps():
    """An IOR seen through a thin glass wall before the checkerboard: its Jacobian column's
    noise is rare large jumps (pixels where an edge is crossed), ten times its signal energy, so
    one pair's cross curvature scatters more than its mean. The estimate, the mean of the steps'
    Newton targets under the pooled curvature, is then within about 10 % of the gradient noise's
    own floor (0.066 here; each point's own curvature, as before: 0.16) and the well-measured
    coordinates twenty times closer; the stated Monte-Carlo errors cover the truth."""
    from abs.fitting.laplace import LaplaceApproximation
    from abs.fitting.optimisers.lm import LevenbergMarquardt

    exact, noisy_for = _rare_jumps_problem()
    optimiser, errors, covered = LevenbergMarquardt(), [], []
    none = LaplaceApproximation(np.zeros((3, 3)), np.zeros(3), np.eye(3), 0.0, np.ones(3, bool))
    for seed in range(30):
        noisy = noisy_for(seed)
        state = gauss_newton_refinement(noisy, OptimizerState("lm", 0, exact + [0.3, 0, 0]), steps=16)
        stated = with_monte_carlo_error(none, optimiser.averaged_points(state),
                                        optimiser.scatter_points(state),
                                        optimiser.sequential_points(state)).stderr
        errors.append(state.z - exact)
        covered.append(np.abs(state.z - exact) < 2 * stated)
    spread = np.std(errors, axis=0)
    assert spread[0] < 0.1 and np.all(spread[1:] < 0.01), spread
    assert np.all(np.mean(covered, axis=0) >= 0.8), np.mean(covered, axis=0)


def test_refinement_of_few_steps_does_not_trust_one_pairs_curvature_of_a_noisy_column():
    """Two refinement steps average one: its Newton target under one pair's unfloored curvature
    of a column that is mostly noise (the rare large jumps above) lands anywhere within four
    trust radii (1.9 RMS over seeds). Below three averaged steps the estimate is the points'."""
    exact, noisy_for = _rare_jumps_problem()
    errors = []
    for seed in range(40):
        state = gauss_newton_refinement(noisy_for(seed), OptimizerState("lm", 0, exact + [0.3, 0, 0]),
                                        steps=2)
        errors.append(state.z - exact)
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    assert rms[0] < 0.8 and np.all(rms[1:] < 0.3), rms


def test_refinement_estimate_stays_finite_for_a_coordinate_the_images_do_not_see():
    """An absorption deep at its bound: its column and gradient are numerical dust (the glass
    suite's distant bowl, whose Newton targets overflowed a float). The targets stay within a
    few trust radii of their points, and the seen coordinates are estimated as usual."""
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A[:, :2], y, rcond=None)[0]
    rng = np.random.default_rng(8)

    def noisy(z, it):
        J = [A + 0.05 * rng.normal(size=A.shape) for _ in range(2)]
        for j in J:
            j[:, 2] = 1e-160 * rng.normal(size=len(y))
        return A[:, :2] @ z[:2] - y + 0.1 * rng.normal(size=len(y)), tuple(J), 0.0

    state = gauss_newton_refinement(noisy, OptimizerState("lm", 0, np.append(exact, -30.0)), steps=12)
    assert np.all(np.isfinite(state.z)), state.z
    assert abs(state.z[2] + 30.0) < 4.0 * 12 * np.max(state.solver.refinement.radius)
    assert np.allclose(state.z[:2], exact, atol=0.05), state.z[:2] - exact


def test_refinement_resumed_from_a_checkpoint_ends_where_one_run_does():
    """The pooled curvature and the Newton targets come from the steps' record, which a
    checkpoint keeps: a refinement stopped after 5 steps and resumed ends at the same estimate."""
    from abs.fitting.optimisers.lm import LMState

    A, y, _ = _linear_problem()

    def noisy(z, it):  # seeded by the step, as the fit's fresh renders are
        rng = np.random.default_rng(it)
        return (A @ z - y + 0.3 * rng.normal(size=len(y)),
                tuple(A + 0.3 * rng.normal(size=A.shape) for _ in range(2)), 0.0)

    start = np.linalg.lstsq(A, y, rcond=None)[0] + 0.5
    whole = gauss_newton_refinement(noisy, OptimizerState("lm", 0, start), steps=12)
    part = gauss_newton_refinement(noisy, OptimizerState("lm", 0, start), steps=5)
    saved = OptimizerState.from_dict(json.loads(json.dumps(part.to_dict())))
    assert isinstance(saved.solver, LMState) and len(saved.solver.refinement.gradients) == 5
    resumed = gauss_newton_refinement(noisy, saved, steps=12)
    assert np.allclose(resumed.z, whole.z, rtol=0, atol=1e-9), resumed.z - whole.z


def test_refinement_that_has_arrived_keeps_averaging_through_late_clipped_steps():
    """Two late steps clipped in the same direction (noise, after the walk has arrived) must not
    reduce the average to the last point."""
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    # A Newton step from z lands on exact - offset: small alternating noise, then two far ones.
    offsets = [0.3 * (-1) ** k * np.ones(3) for k in range(10)] + [np.full(3, -3.0)] * 2

    def steered(z, it):  # ``it`` counts the steps from 1
        return A @ z - y + A @ offsets[it - 1], (A, A), 0.0

    state = gauss_newton_refinement(steered, OptimizerState("lm", 0, exact.copy()), steps=12)
    clipped = state.solver.refinement.clipped
    assert not any(clipped[-3:]), clipped
    # The estimate is the mean of the averaged steps' Newton targets (all but the first
    # quarter): with an exact Jacobian step k's target is exact - offsets[k], clipped or not.
    assert np.allclose(state.z, exact - np.mean(offsets[3:], axis=0)), state.z - exact


def test_cross_curvature_is_unbiased_where_the_self_product_is_not():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(200, 3))
    draws = [J + rng.normal(size=J.shape) for _ in range(400)]
    cross = np.mean([cross_curvature(draws[i], draws[i + 1]) for i in range(0, 400, 2)], axis=0)
    self_product = np.mean([d.T @ d for d in draws], axis=0)
    truth = J.T @ J
    assert np.allclose(np.diag(cross), np.diag(truth), rtol=0.05)
    assert np.all(np.diag(self_product) > 1.5 * np.diag(truth))


def test_cross_curvature_keeps_small_columns_curvature_beside_large_ones():
    """An environment scale's column is ~60x an absorption's: the positive-definite floor must
    not raise the small column's curvature (it had, fivefold, and steps went a fifth of the way)."""
    rng = np.random.default_rng(4)
    J = np.column_stack([60.0 * rng.normal(size=500), rng.normal(size=500)])
    H = cross_curvature(J + 0.01 * rng.normal(size=J.shape), J + 0.01 * rng.normal(size=J.shape))
    truth = J.T @ J
    assert H[1, 1] == pytest.approx(truth[1, 1], rel=0.02)
    assert np.linalg.solve(H, truth[:, 1]) == pytest.approx([0.0, 1.0], abs=0.02)


def test_adam_converges_and_resumes_from_its_state():
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]

    def grad(z, it):
        r = A @ z - y
        return float(np.sqrt(np.mean(r ** 2))), A.T @ r / len(y)

    full = adam(grad, OptimizerState("adam", 0, np.zeros(3)), 300, learning_rate=0.05)
    assert np.allclose(full.z, exact, atol=0.02)
    saved = {}

    def interrupt(state):
        if state.iteration == 150:
            saved.update(json.loads(json.dumps(state.to_dict())))  # as a checkpoint file has it
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        adam(grad, OptimizerState("adam", 0, np.zeros(3)), 300, learning_rate=0.05, on_iteration=interrupt)
    resumed = adam(grad, OptimizerState.from_dict(saved), 300, learning_rate=0.05)
    assert np.allclose(resumed.z, full.z, rtol=1e-12, atol=1e-12)


def test_laplace_from_two_renders_leaves_the_renders_noise_out():
    """A noisy estimator of a fixed dataset: the photographs' noise (0.05 per pixel) is the
    data's, the renders' (0.2) is the estimator's, measured by its own scatter. From two
    independent renders' residuals ``sigma`` is the photographs'; together with the measured
    Monte-Carlo part the standard errors then cover at their stated rate, where ``|r|^2`` alone
    counts the renders' noise twice and makes them about twice too wide."""
    rng = np.random.default_rng(4)
    A = rng.normal(size=(400, 3))
    truth = np.array([1.0, -2.0, 0.5])
    inside = [], []  # within one standard error: (two renders, one render)
    for trial in range(200):
        photo = A @ truth + 0.05 * rng.normal(size=400)
        # Each refinement target fits the photograph plus one render's noise.
        targets = [np.linalg.lstsq(A, photo + 0.2 * rng.normal(size=400), rcond=None)[0]
                   for _ in range(12)]
        estimate = np.mean(targets, axis=0)
        r1, r2 = (A @ estimate + 0.2 * rng.normal(size=400) - photo for _ in range(2))
        for inside_k, other in zip(inside, (r2, None)):
            approx = with_monte_carlo_error(laplace(r1, A, residuals2=other), np.array(targets))
            inside_k.append(np.abs(estimate - truth) < approx.stderr)
    two, one = np.mean(inside[0]), np.mean(inside[1])
    assert 0.6 < two < 0.76 and one > 0.85, (two, one)  # 1 s.e.: 68 %
    assert abs(laplace(r1, A, residuals2=r2).pixel_sigma - 0.05) < 0.03


def test_laplace_matches_the_linear_gaussian_posterior():
    A, y, truth = _linear_problem(m=400, noise=0.2)
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    approx = laplace(A @ exact - y, A)
    sigma2 = np.sum((A @ exact - y) ** 2) / (len(y) - 3)
    assert np.allclose(approx.covariance, sigma2 * np.linalg.inv(A.T @ A), rtol=1e-8)
    assert abs(approx.pixel_sigma - 0.2) < 0.03
    assert np.all(np.abs(exact - truth) < 4 * approx.stderr)
    # A parameter the data do not see has no standard error (not a made-up one)...
    blind = laplace(A @ exact - y, np.column_stack([A, np.zeros(len(y))]))
    assert np.isnan(blind.stderr[3]) and np.all(np.isfinite(blind.stderr[:3]))
    # ...unless a prior constrains it.
    prior = laplace(A @ exact - y, np.column_stack([A, np.zeros(len(y))]), np.array([np.inf] * 3 + [0.5]))
    assert prior.stderr[3] == pytest.approx(0.5)


def test_downsampled_camera_sees_the_block_centres():
    from abs.render.camera import Camera

    K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    cam = Camera(K, np.eye(3), np.zeros(3), 64, 48)
    low = downsample_camera(cam, 4)
    point = np.array([0.05, -0.02, 1.0])
    u, v, w = cam.K @ point
    ul, vl, wl = low.K @ point
    # High-resolution pixel x lies in low-resolution pixel x // 4 at (x - 1.5) / 4.
    assert np.allclose([ul / wl, vl / wl], [(u / w - 1.5) / 4, (v / w - 1.5) / 4])
    assert (low.width, low.height) == (16, 12)
    image = np.arange(64 * 48 * 3, dtype=float).reshape(48, 64, 3)
    assert downsample(image, 4)[1, 2, 0] == image[4:8, 8:12, 0].mean()


def test_noise_estimate_of_white_noise():
    rng = np.random.default_rng(0)
    ramp = np.linspace(0, 1, 128)[None, :, None] * np.ones((96, 128, 3))
    assert estimate_image_noise(ramp + 0.05 * rng.normal(size=ramp.shape)) == pytest.approx(0.05, rel=0.05)


def test_schedules():
    s = parse_schedule("10:16, 0:4")
    assert s == ((0, 4), (10, 16))
    assert [schedule_value(s, i, 8) for i in (0, 9, 10, 50)] == [4, 4, 16, 16]
    with pytest.raises(ValueError, match="ITERATION:VALUE"):
        parse_schedule("ten:4")


def test_checkpoint_belongs_to_its_fit(tmp_path):
    identity = {"scene": "a.toml", "parameters": ["glass.ior"]}
    save_checkpoint(tmp_path, identity, OptimizerState("lm", 3, np.ones(3)).to_dict())
    assert OptimizerState.from_dict(load_checkpoint(tmp_path, identity)).iteration == 3
    with pytest.raises(InputError, match="fit.parameters"):
        load_checkpoint(tmp_path, {**identity, "parameters": ["glass.absorption"]})
    (tmp_path / "checkpoint.json").write_text("{broken")
    with pytest.raises(InputError, match="checkpoint"):
        load_checkpoint(tmp_path, identity)
    assert load_checkpoint(tmp_path / "none", identity) is None


def test_a_downsampled_camera_renders_the_box_average_of_the_fine_image(small_scene_dir):
    from abs import load_scene
    from abs.render import Camera, compile_scene
    from abs.simulate import place_cameras

    compiled = compile_scene(load_scene(small_scene_dir / "scene.toml"))
    view = place_cameras(compiled, 1, 48, 36)[0]
    fine = Camera(view["K"], view["R"], view["t"], 48, 36)
    coarse = downsample_camera(fine, 3)
    assert coarse.block == 3
    expected = downsample(compiled.render(fine, spp=256, seed=1).numpy(), 3)
    got = compiled.render(coarse, spp=2304, seed=2).numpy()
    plain = compiled.render(Camera(coarse.K, coarse.R, coarse.t, 16, 12), spp=2304, seed=2).numpy()
    err, err_plain = np.sqrt(np.mean((got - expected) ** 2)), np.sqrt(np.mean((plain - expected) ** 2))
    assert err < 0.6 * err_plain, (err, err_plain)  # the plain tent filter blurs differently


@pytest.mark.slow
def test_reverse_mode_gradient_equals_the_forward_mode_jacobian_product(small_scene_dir, tmp_path):
    from abs.model import build_model
    from abs.simulate import simulate_capture

    from abs import load_scene

    scene = load_scene(small_scene_dir / "scene.toml")
    capture = simulate_capture(scene, tmp_path / "capture", n_cameras=2, width=24,
                               height=18, spp=32, n_holdout=0, seed=5)
    names = ["environment.scale", "glass.absorption"]
    model = build_model(scene, capture, names)
    vector = model.vector
    problem = model.problem("train", clamp=0.9)
    theta = vector.initial * np.array([1.2, 0.7, 1.3, 0.9])  # away from the truth: r is not noise
    r, J = problem.residuals(theta, 4, seed=3, jacobian=True, jacobian_seed=8)
    half, g = problem.gradient(theta, 4, seed=3, jacobian_seed=8)
    assert half == pytest.approx(0.5 * r @ r, rel=1e-6)
    assert np.allclose(g, J.T @ r, rtol=2e-3, atol=1e-4 * np.abs(J.T @ r).max())


def test_monte_carlo_error_of_averaged_points_adds_to_the_laplace_covariance():
    A, y, _ = _linear_problem()
    exact = np.linalg.lstsq(A, y, rcond=None)[0]
    approx = laplace(A @ exact - y, A)
    points = exact + np.random.default_rng(3).normal(scale=0.2, size=(400, 3))
    combined = with_monte_carlo_error(approx, points)
    expected = np.sqrt(approx.stderr ** 2 + 0.2 ** 2 / 400)
    assert np.allclose(combined.stderr, expected, rtol=0.1)
    assert with_monte_carlo_error(approx, points[:1]) is approx


def test_optimisers_are_registered_by_file_name_and_checked_by_the_settings():
    from abs.fitting.optimisers import get, names
    from abs.fitting.optimisers.adam import Adam
    from abs.fitting.optimisers.lm import LevenbergMarquardt
    from abs.fitting.settings import FitSettings

    assert names() == ("adam", "lm")
    assert isinstance(get("lm"), LevenbergMarquardt) and isinstance(get("adam"), Adam)
    with pytest.raises(ValueError, match="unknown optimiser"):
        get("newton")
    with pytest.raises(ValueError, match="method must be auto, adam or lm"):
        FitSettings(method="newton")


def test_optimiser_states_are_typed_and_read_checkpoints_in_the_dictionary_format():
    """Checkpoints written when the optimiser state was a dictionary named ``moments`` resume."""
    from abs.fitting.optimisers.adam import AdamState
    from abs.fitting.optimisers.lm import LMState

    old = {"method": "lm", "iteration": 7, "z": [0.5, -1.0], "history": [],
           "moments": {"lm_converged": True, "refinement": [[0.4, -1.1], [0.45, -1.05]],
                       "refinement_clipped": [True, False], "refinement_radius": 2.0,
                       "refinement_step": [0.05, 0.05]}}
    state = OptimizerState.from_dict(old)
    assert isinstance(state.solver, LMState) and state.solver.converged
    assert state.solver.refinement.clipped == (True, False) and state.solver.refinement.radius == 2.0
    assert json.loads(json.dumps(state.to_dict())) == old
    fresh = OptimizerState.from_dict({"method": "lm", "iteration": 3, "z": [0.0], "moments": {}})
    assert fresh.solver is None and fresh.to_dict()["moments"] == {}
    adam_old = {"method": "adam", "iteration": 2, "z": [1.0], "history": [],
                "moments": {"m": [0.1], "v": [0.01], "tail_sum": [0.0], "tail_count": 0}}
    state = OptimizerState.from_dict(adam_old)
    assert isinstance(state.solver, AdamState) and state.to_dict() == adam_old


def test_laplace_flags_only_scalars_in_unresolved_directions():
    """A column that is pure Monte-Carlo noise in two independent Jacobians (an IOR seen through
    glass at low spp) has no resolvable curvature; the well-determined scalars beside it keep
    their standard errors, and more Jacobian pairs are averaged into the curvature."""
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(2, 400))
    residuals = 0.1 * rng.normal(size=400)

    def jacobian():
        return np.column_stack([a, b, 0.5 * rng.normal(size=400)])

    approx = laplace(residuals, jacobian(), jacobian2=jacobian())
    assert approx.identifiable.tolist() == [True, True, False]
    assert np.all(np.isfinite(approx.stderr[:2])) and np.isnan(approx.stderr[2])
    # The noise column's cross curvature averages towards zero with more pairs; the others stay.
    more = laplace(residuals, jacobian(), jacobian2=jacobian(),
                   more_pairs=[(jacobian(), jacobian()) for _ in range(3)])
    assert more.identifiable[:2].all()
    np.testing.assert_allclose(more.stderr[:2], approx.stderr[:2], rtol=0.2)


def test_monte_carlo_error_of_few_averaged_points_takes_a_wider_scatter():
    """One arrived point says nothing of the refinement's spread: the scatter comes from the
    wider set of iterates (conservative), divided by the number actually averaged."""
    A, y, _ = _linear_problem()
    approx = laplace(A @ np.linalg.lstsq(A, y, rcond=None)[0] - y, A)
    rng = np.random.default_rng(5)
    wide = rng.normal(scale=0.2, size=(8, A.shape[1]))
    alone = with_monte_carlo_error(approx, wide[-1:])
    np.testing.assert_allclose(alone.stderr, approx.stderr)  # nothing to scatter: unchanged
    widened = with_monte_carlo_error(approx, wide[-1:], scatter=wide)
    expected = np.sqrt(approx.stderr ** 2 + np.var(wide, axis=0, ddof=1))
    np.testing.assert_allclose(widened.stderr, expected, rtol=1e-9)


def test_refinement_records_the_coordinates_its_noise_moves():
    """A coordinate whose Jacobian column is Monte-Carlo noise alone (the glass suite's bowl IOR at
    64 spp: columns of independent renders with cosine 0.01) has Newton steps of any length:
    they are cut to the trust radius nearly every step (10 of 11 for the bowl), while measured
    coordinates' are not. The record survives a checkpoint."""
    from abs.fitting.optimisers.lm import LevenbergMarquardt, LMState

    A, y, _ = _linear_problem()
    A[:, :2] *= 10.0  # two well-measured coordinates
    A[:, 2] = 0.0  # the images do not depend on the third one
    rng = np.random.default_rng(7)

    def noisy(z, it):  # pixel noise 2, Jacobian noise 0.1; the third column is noise alone
        J = [A + 0.1 * rng.normal(size=A.shape) for _ in range(2)]
        for j in J:
            j[:, 2] = 0.3 * rng.normal(size=len(y))
        return A @ z - y + 2.0 * rng.normal(size=len(y)), tuple(J), 0.0

    start = np.append(np.linalg.lstsq(A[:, :2], y, rcond=None)[0], 0.0)
    state = gauss_newton_refinement(noisy, OptimizerState("lm", 0, start), steps=16)
    share = LevenbergMarquardt().limited_steps(state).mean(axis=0)
    # Over 30 seeds: the noise coordinate 0.67-1.0 (mean 0.83), the measured ones at most 0.25.
    assert share[2] >= 0.75 and np.all(share[:2] <= 0.25), share
    again = LMState.from_dict(json.loads(json.dumps(state.solver.to_dict())))
    assert again.refinement.limited == state.solver.refinement.limited


def test_refinement_curvatures_resolve_a_noisy_column_in_the_laplace_units():
    """The refinement keeps each step's cross curvature (in ``z``, of the weighted residuals and
    the priors' rows); converted back they estimate the pixel curvature ``J^T J`` in physical
    units, and their average resolves a column that one pair at the optimum cannot (the framed
    bowl's IOR through glass). The record survives a checkpoint."""
    from types import SimpleNamespace

    from abs.fitting.fit import _refinement_curvatures
    from abs.fitting.optimisers.lm import LevenbergMarquardt, LMState

    vector = _vector()
    p = vector.size
    rng = np.random.default_rng(3)
    J_theta = rng.normal(size=(300, p))
    J_theta[:, 0] *= 0.05  # a weak column (an IOR whose pixels are few)
    sigma, prior_sd = 0.2, np.full(p, np.inf)
    prior_sd[4] = 0.5
    objective = SimpleNamespace(vector=vector, sigma=sigma, prior_sd=prior_sd,
                                has_prior=np.isfinite(prior_sd))
    has = np.isfinite(prior_sd)
    z0 = vector.to_unconstrained(vector.to_physical(np.zeros(p)) + 0.01)

    def weighted(z, noise):  # the objective's Jacobian in z: J dtheta/dz / sigma, prior rows below
        d = vector.derivative(z)
        J = (J_theta + noise * rng.normal(size=J_theta.shape)) * d / sigma
        return np.concatenate([J, np.diag(d / prior_sd)[has]])

    def evaluate(z, it):
        return np.zeros(300 + has.sum()), (weighted(z, 0.3), weighted(z, 0.3)), 0.0

    state = gauss_newton_refinement(evaluate, OptimizerState("lm", 0, z0), steps=40, max_step=1e-9)
    found = LevenbergMarquardt().curvatures(state)
    assert found is not None and len(found[0]) == 30  # all but the first quarter
    mean = np.mean(_refinement_curvatures(found, objective), axis=0)
    exact = J_theta.T @ J_theta
    scale = np.sqrt(np.outer(np.diag(exact), np.diag(exact)))
    # 30 pairs with Jacobian noise 0.3 per entry: within a few of their standard errors.
    assert np.all(np.abs(mean - exact) < 6 * 0.3 * np.sqrt(300 / 30) * np.sqrt(scale) + 1e-9)
    assert mean[0, 0] == pytest.approx(exact[0, 0], rel=0.5)
    # One noisy pair at the optimum often leaves the weak column's curvature unresolved (about
    # a third of pairs); with the refinement's pairs the Laplace approximation resolves it.
    nearby = _refinement_curvatures(found, objective)
    alone = together = 0
    for _ in range(20):
        r = 0.01 * rng.normal(size=300)
        pair = [J_theta + 0.3 * rng.normal(size=J_theta.shape) for _ in range(2)]
        alone += not laplace(r, pair[0], jacobian2=pair[1]).identifiable.all()
        together += not laplace(r, pair[0], jacobian2=pair[1], curvatures=nearby).identifiable.all()
    assert alone >= 3 and together == 0, (alone, together)
    again = LMState.from_dict(json.loads(json.dumps(state.solver.to_dict())))
    assert np.allclose(np.array(again.refinement.curvatures), np.array(state.solver.refinement.curvatures))
    assert np.allclose(np.array(again.refinement.curvature_at),
                       np.array(state.solver.refinement.curvature_at))


def test_monte_carlo_error_of_a_walk_covers_its_mean():
    """Sequential iterates that walk (AR(1), autocorrelation 0.7, as the distant bowl's IOR) have
    a mean that varies far more than ``cov / n``: corrected by the autocorrelation, the error
    covers the truth at about the stated rate; independent scatter keeps ``cov / n``."""
    rng = np.random.default_rng(5)
    base = laplace(np.full(50, 1e-3), np.eye(50, 1) * 1e3)  # a negligible Laplace part
    covered_walk = covered_plain = 0
    trials, n, rho = 400, 12, 0.7
    for _ in range(trials):
        x = np.empty(n)
        x[0] = rng.normal() / np.sqrt(1 - rho ** 2)
        for i in range(1, n):
            x[i] = rho * x[i - 1] + rng.normal()
        err = with_monte_carlo_error(base, x[:, None], sequential=True).stderr[0]
        naive = with_monte_carlo_error(base, x[:, None]).stderr[0]
        covered_walk += abs(x.mean()) <= 1.96 * err
        covered_plain += abs(x.mean()) <= 1.96 * naive
    # cov / n alone covers about half the time; the correction brings it to about 80 % (the
    # variance from 12 correlated points is still low, so short of 95 %).
    assert covered_plain / trials < 0.65
    assert covered_walk / trials > 0.74, covered_walk / trials
    independent = rng.normal(size=(12, 1))
    assert (with_monte_carlo_error(base, independent, sequential=True).stderr[0]
            <= with_monte_carlo_error(base, independent).stderr[0] * 1.6)


def test_laplace_does_not_depend_on_a_parameters_units():
    """A scalar in units 1e6 times smaller (an environment scale fitted in data numbers per
    second) is as identifiable as before, its standard error 1e6 times larger."""
    rng = np.random.default_rng(4)
    J = rng.normal(size=(400, 3))
    r = rng.normal(0, 0.1, 400)
    base = laplace(r, J)
    units = np.array([1.0, 1.0, 1e-6])  # d r / d (scaled scalar)
    scaled = laplace(r, J * units)
    assert scaled.identifiable.all()
    np.testing.assert_allclose(scaled.stderr, base.stderr / units, rtol=1e-6)
    # A direction the photographs really do not see is still refused.
    J2 = J.copy()
    J2[:, 2] = J2[:, 1]
    assert not laplace(r, J2).identifiable[1:].any()


def test_laplace_sandwich_covers_correlated_noise():
    """Least squares on pixels whose noise is spread between neighbours (a moving average, as
    demosaicing spreads a site's noise): the plain Laplace covariance is too small, the sandwich
    with the noise's correlation matches the estimates' spread over noise draws."""
    rng = np.random.default_rng(7)
    M = 600
    J = np.column_stack([np.ones(M), np.sin(np.arange(M) / 40.0)])
    A = sum(np.eye(M, k=k) for k in (-2, -1, 0, 1, 2)) / np.sqrt(5)  # unit-variance moving average
    K = A @ A.T
    estimates, last = [], None
    for _ in range(400):
        noise = A @ rng.normal(0, 0.1, M)
        theta, *_ = np.linalg.lstsq(J, noise, rcond=None)
        estimates.append(theta)
        last = noise - J @ theta
    spread = np.std(estimates, axis=0)
    plain = laplace(last, J).stderr
    sandwich = laplace(last, J, jacobian2=J, correlation=lambda X: K @ X).stderr
    assert np.all(plain < 0.6 * spread)
    np.testing.assert_allclose(sandwich, spread, rtol=0.15)
