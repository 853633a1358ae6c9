"""The forward model package: below fitting, sampling and diagnosis, built by one factory."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import abs as abs_package
from abs.errors import InputError

MODEL = Path(abs_package.__file__).parent / "model"


def test_the_model_imports_nothing_that_sits_above_it():
    above = ("abs.fitting", "abs.sampling", "abs.diagnosis")
    edges = []
    for path in sorted(MODEL.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):  # function-local imports included
            modules = ([a.name for a in node.names] if isinstance(node, ast.Import)
                       else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            edges += [f"{path.name} -> {m}" for m in modules if m.startswith(above)]
    assert not edges, edges


@pytest.fixture(scope="module")
def capture(small_scene_dir, tmp_path_factory):
    from abs import load_scene
    from abs.simulate import simulate_capture

    return simulate_capture(load_scene(small_scene_dir / "scene.toml"),
                            tmp_path_factory.mktemp("model") / "capture", n_cameras=3, width=16,
                            height=12, spp=8, n_holdout=1, seed=2)


def test_build_model_lays_out_the_parameters_and_shares_one_counter(small_scene_dir, capture):
    from abs.model import build_model

    model = build_model(small_scene_dir / "scene.toml", capture,
                        ["environment.scale", "glass.absorption"], {"environment.scale": [1.25]})
    assert model.names == ("environment.scale", "glass.absorption") and model.vector.size == 4
    assert model.vector.initial[0] == pytest.approx(1.25)
    train, holdout = model.problem("train", 2), model.problem("holdout")
    assert model.problem("train", 2) is train  # photographs are read once per resolution
    assert [o.holdout for o in train.observations] == [False, False]
    assert [o.holdout for o in holdout.observations] == [True]
    assert train.observations[0].photograph.shape == (6, 8, 3)
    assert len(model.problem("all").observations) == 3
    train.residuals(model.vector.initial, 1, seed=0)
    holdout.residuals(model.vector.initial, 1, seed=0)
    assert model.counter.renders == 3 and train.counter is holdout.counter is model.counter
    with pytest.raises(ValueError, match="views"):
        model.problem("test")


def test_build_model_refuses_what_cannot_be_fitted(small_scene_dir, capture):
    from abs.model import build_model

    with pytest.raises(InputError, match="unknown parameter"):
        build_model(small_scene_dir / "scene.toml", capture, ["glass.colour"])
    with pytest.raises(InputError, match="not among the fitted parameters"):
        build_model(small_scene_dir / "scene.toml", capture, ["environment.scale"],
                    {"glass.absorption": [1.0, 1.0, 1.0]})
    with pytest.raises(InputError, match="initial.glass.absorption"):
        build_model(small_scene_dir / "scene.toml", capture, ["glass.absorption"],
                    {"glass.absorption": np.ones(2)})


def test_pixel_weights_give_the_maximum_likelihood_fit_under_uneven_noise(small_scene_dir, capture):
    """Photographs whose noise is 100 times larger on 3 % of their pixels (glints, in a merged
    bracket): weighing residuals by the capture's noise images gives the scale's weighted
    least-squares estimate, whose scatter over noise draws is the one its theory states and far
    below the unweighted fit's."""
    from dataclasses import replace

    from abs.model import FitProblem, build_model
    from abs.model.problem import _view_seed

    model = build_model(small_scene_dir / "scene.toml", capture, ["environment.scale"])
    plain = model.problem("train")
    theta = model.vector.initial
    # The images the residuals below render (their seeds): the photographs' noise is all there is.
    clean = [plain.render(o, theta, 16, _view_seed(4, k)) for k, o in enumerate(plain.observations)]
    rng = np.random.default_rng(0)
    sds = [np.where(rng.uniform(size=c.shape[:2] + (1,)) < 0.03, 0.5, 0.005) * np.ones_like(c)
           for c in clean]
    weighted = FitProblem(model.compiled, model.vector,
                          [replace(o, noise_sd=sd) for o, sd in zip(plain.observations, sds)])
    assert weighted.weights is not None and plain.weights is None
    # Relative to the median noise, with the median variance added: typical pixels weigh 1, the
    # noisy ones about 1/70.
    w = np.concatenate([wk[o.mask].ravel() for wk, o in zip(weighted.weights, weighted.observations)])
    assert np.median(w) == pytest.approx(1.0)
    assert w.min() == pytest.approx(np.sqrt(2) * 0.005 / np.hypot(0.5, 0.005))

    estimates = {"plain": [], "weighted": []}
    for _ in range(40):
        photos = [c + sd * rng.normal(size=c.shape) for c, sd in zip(clean, sds)]
        for label, problem in (("plain", plain), ("weighted", weighted)):
            problem.observations[:] = [replace(o, photograph=p)
                                       for o, p in zip(problem.observations, photos)]
            # The rendering is linear in the scale: one Gauss-Newton step is the least-squares fit.
            r, J = problem.residuals(theta, 16, seed=4, jacobian=True)
            estimates[label].append(theta[0] - (J[:, 0] @ r) / (J[:, 0] @ J[:, 0]))
    # Least squares with weights w: var = sum w^4 J^2 sd^2 / (sum w^2 J^2)^2, here within 5 % of
    # the best any weights give (1 / sum (J / sd)^2, weights 1 / sd).
    J = plain.jacobian(theta, 16, seed=4)[:, 0]
    sd_rows = np.concatenate([sd[o.mask].ravel() for sd, o in zip(sds, plain.observations)])
    stated = np.sqrt(np.sum(w ** 4 * J ** 2 * sd_rows ** 2)) / np.sum(w ** 2 * J ** 2)
    assert stated < 1.05 / np.sqrt(np.sum((J / sd_rows) ** 2))
    scatter = {k: float(np.std(v, ddof=1)) for k, v in estimates.items()}
    assert abs(np.mean(estimates["weighted"]) - theta[0]) < 3 * stated / np.sqrt(40)
    assert 0.75 < scatter["weighted"] / stated < 1.3, (scatter, stated)  # 40 draws: +- 11 %
    assert scatter["plain"] > 3 * scatter["weighted"], scatter
    # The reverse-mode gradient weighs alike (Adam's path, path replay: without recordings,
    # which would give J^T r from residuals() itself): J^T W^2 r.
    # Weights that vary over the image (shot-noise-like), so that w and w^2 differ everywhere.
    varied = [replace(o, noise_sd=0.005 * (0.2 + c)) for o, c in zip(weighted.observations, clean)]
    replay = FitProblem(model.compiled, model.vector, varied, reweight=False)
    assert not replay.uses_recordings and np.ptp(replay.weights[0][replay.observations[0].mask]) > 0.5
    half, g = replay.gradient(theta * 1.1, 16, seed=4, jacobian_seed=4)
    r, J = replay.residuals(theta * 1.1, 16, seed=4, jacobian=True)
    assert half == pytest.approx(0.5 * r @ r, rel=1e-6)
    assert g == pytest.approx(J.T @ r, rel=2e-3)


def test_the_samplers_render_variance_is_weighed_as_its_residuals_are(small_scene_dir, capture):
    """The sampler's likelihood adds the renders' variance to the photographs' per residual: with
    noise images, both in the weighted residuals' units (w^2 times the rendered variance)."""
    from dataclasses import replace

    from abs.model import FitProblem, build_model
    from abs.sampling.sample import _estimate_noise

    model = build_model(small_scene_dir / "scene.toml", capture, ["environment.scale"])
    plain = model.problem("train")
    theta = model.vector.initial
    varied = [replace(o, noise_sd=0.005 * (0.2 + o.photograph)) for o in plain.observations]
    weighted = FitProblem(model.compiled, model.vector, varied)
    unweighted = FitProblem(model.compiled, model.vector, [replace(o, noise_sd=None) for o in varied])
    a = _estimate_noise(weighted, theta, 4, 7, 3)
    b = _estimate_noise(unweighted, theta, 4, 7, 3)
    for k, w in enumerate(weighted.weights):
        np.testing.assert_allclose(a.render_variance[k], b.render_variance[k] * w ** 2, rtol=1e-6,
                                   atol=1e-12)
    assert np.ptp(weighted.weights[0][weighted.observations[0].mask]) > 0.5
