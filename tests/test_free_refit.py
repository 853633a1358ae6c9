"""Levenberg-Marquardt refits the parameters that path-length recordings reweight between renders
when others (an IOR) need renders: the refit renders nothing, and leaves the two-seed objective
at its minimum over those parameters."""

from __future__ import annotations

import numpy as np
import pytest

from abs import load_scene
from abs.fitting import FitSettings
from abs.fitting.objective import Objective
from abs.fitting.optimisers import OptimizerState
from abs.fitting.optimisers.lm import free_refit, levenberg_marquardt
from abs.model import build_model
from abs.simulate import simulate_capture
from conftest import (make_backdrop, make_checker, make_env, make_sphere_and_floor, sphere_scene_toml,
                      with_second_glass)

FITTED = ["glass.ior", "glass.absorption", "environment.scale"]


def _linear(seed=0, m=120):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, 3))
    b = A @ np.array([1.0, -2.0, 0.5])
    return A, b


def test_refit_hook_is_applied_before_every_evaluation_and_the_result_kept():
    """With a refit that solves coordinates 1 and 2 exactly (a linear least-squares problem),
    Levenberg-Marquardt only has coordinate 0 left to find, and every point it evaluated was
    refitted first."""
    A, b = _linear()
    evaluated = []

    def evaluate(z, iteration):
        evaluated.append(np.array(z))
        r = A @ z - b
        return (r, A), (r, A), float(np.sqrt(np.mean(r ** 2)))

    def refit(z):
        out = np.array(z, float)
        out[1:] = np.linalg.lstsq(A[:, 1:], b - A[:, 0] * z[0], rcond=None)[0]
        return out

    state = levenberg_marquardt(evaluate, OptimizerState("lm", 0, np.zeros(3)), 30, refit=refit)
    np.testing.assert_allclose(state.z, [1.0, -2.0, 0.5], atol=1e-6)
    for z in evaluated:
        np.testing.assert_allclose(z, refit(z), atol=1e-9)


@pytest.mark.slow
def test_free_refit_renders_nothing_and_minimises_over_the_reweightable_parameters(tmp_path):
    make_sphere_and_floor(tmp_path)
    make_backdrop(tmp_path)
    make_env(tmp_path / "env.exr")
    make_checker(tmp_path / "checker.png")
    text = sphere_scene_toml(FITTED, absorption=[1.0, 1.0, 1.0])
    (tmp_path / "truth.toml").write_text(
        text.replace("ior = [1.5, 1.5, 1.5]", "ior = [1.52, 1.52, 1.52]")
            .replace("absorption = [1.0, 1.0, 1.0]", "absorption = [12.0, 6.0, 2.0]"))
    (tmp_path / "start.toml").write_text(text.replace("scale = 1.0", "scale = 1.3"))
    simulate_capture(load_scene(tmp_path / "truth.toml"), tmp_path / "capture", n_cameras=2,
                     width=48, height=36, spp=256, shot_noise=1e-4, read_noise=0.003, seed=2)
    settings = FitSettings(spp=16, tie=("glass.ior",), max_iterations=5)
    model = build_model(tmp_path / "start.toml", tmp_path / "capture", FITTED, tied=settings.tie)
    objective = Objective.build(model, settings, sigma=0.01, priors={})
    vector = model.vector
    free = objective.free
    assert [vector.labels()[i] for i in range(vector.size) if i not in free] == ["glass.ior (tied)"]

    z0 = vector.to_unconstrained(vector.initial)

    def objective_at(z):  # the two-seed objective and its gradient, as LM sees them
        ra, Ja, _ = objective.residuals(z, 0)
        rb, Jb, _ = objective.residuals(z, 7)
        return 0.5 * float(ra @ rb), 0.5 * (Ja.T @ rb + Jb.T @ ra)

    f0, g0 = objective_at(z0)
    renders = model.counter.renders
    z1 = free_refit(objective, z0, 0, settings.downsample)
    assert model.counter.renders == renders  # the recordings at z0's IOR served every evaluation
    np.testing.assert_array_equal(np.delete(z1, free), np.delete(z0, free))  # the IOR held
    f1, g1 = objective_at(z1)
    assert f1 < 0.5 * f0, (f0, f1)
    # At the minimum over the free scalars their gradient has vanished (relative to the start).
    assert np.max(np.abs(g1[free])) < 1e-2 * np.max(np.abs(g0[free])), (g0[free], g1[free])
    # The absorption moved towards the truth's ordering (red most absorbed).
    absorption = vector.split(vector.to_physical(z1))["glass.absorption"]
    assert absorption[0] > absorption[1] > absorption[2], absorption


def test_two_glasses_are_recorded_jointly(tmp_path):
    """With two glass materials' absorptions fitted, recordings keep both glasses' lengths (one
    joint histogram): both absorptions and the scale are free of renders, and the Jacobian
    columns agree with a fit that renders everything."""
    make_sphere_and_floor(tmp_path)
    make_backdrop(tmp_path)
    make_env(tmp_path / "env.exr")
    make_checker(tmp_path / "checker.png")
    text = sphere_scene_toml(["glass.absorption", "tint.absorption", "environment.scale"],
                             absorption=[3.0, 3.0, 3.0])
    text = with_second_glass(text)
    (tmp_path / "scene.toml").write_text(text)
    simulate_capture(load_scene(tmp_path / "scene.toml"), tmp_path / "capture", n_cameras=2,
                     width=24, height=18, spp=16, seed=2)
    recorded = build_model(tmp_path / "scene.toml", tmp_path / "capture")
    problem = recorded.problem()
    assert problem.recorded_materials == ("glass", "tint")
    assert problem.reweightable == ["glass.absorption", "tint.absorption", "environment.scale"]
    assert problem.uses_recordings
    theta = recorded.vector.initial
    obs = problem.observations[0]
    image, jac = problem._render_with_jacobian(obs, theta, 64, 3)
    renders = recorded.counter.renders
    # Other absorptions of either glass: the same recording, no render.
    moved = theta.copy()
    moved[:3] *= 1.5
    moved[3:6] *= 1.5
    problem.render(obs, moved, 64, 3)
    assert recorded.counter.renders == renders
    # The same columns from renders only (forward mode): the recorded ones (made at absorption
    # 0, with the same roulette decisions) agree to the joint length binning's error (nodes
    # 30 mm apart: at most 1.1 % for the tint's 10 per metre).
    plain = build_model(tmp_path / "scene.toml", tmp_path / "capture", reweight=False)
    _, jac_p = plain.problem()._render_with_jacobian(plain.problem().observations[0], theta, 64, 3)
    for i in range(jac.shape[-1]):
        scale = np.abs(jac_p[..., i]).sum()
        difference = np.abs(jac[..., i] - jac_p[..., i]).sum() / scale
        assert scale > 0 and difference < 2e-2, (i, difference)
