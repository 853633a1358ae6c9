"""Planned measurement directions: the greedy A-optimal plan reconstructs held-out materials better
than random directions, and its expected error is the one its formula gives."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import analytic_tables

from abs.brdf.design import CRITERIA, expected_error, pair_weighted_gram, plan_directions
from abs.brdf.directions import merl_entries, merl_entry_measure, uniform_hemisphere_directions
from abs.brdf.pca import build_basis
from abs.brdf.reconstruct import default_eta, fit_coefficients


@pytest.fixture(scope="module")
def basis_and_held_out():
    training = analytic_tables(8, seed=2)
    names = [f"m{j}" for j in range(len(training))]
    basis = build_basis(names, dict(zip(names, training)).__getitem__, n_components=5)
    return basis, analytic_tables(8, seed=7)


@pytest.mark.parametrize("criterion", sorted(CRITERIA))
def test_plan_expected_error_matches_its_formula(basis_and_held_out, criterion):
    basis, _ = basis_and_held_out
    plan = plan_directions(basis, 6, candidates=3000, rng=1, criterion=criterion)
    assert plan.criterion == criterion
    gram = pair_weighted_gram(basis, criterion)
    direct = [np.sqrt(expected_error(basis, merl_entries(plan.wi[:n], plan.wo[:n]), gram=gram))
              for n in range(1, 7)]
    np.testing.assert_allclose(plan.expected_rmse, direct, rtol=1e-6)
    # Every added pair lowers the expected error; no pair is chosen twice.
    assert np.all(np.diff(plan.expected_rmse) < 0)
    assert len({tuple(e) for e in merl_entries(plan.wi, plan.wo)}) == 6
    assert np.all(plan.wi[:, 2] > 0) and np.all(plan.wo[:, 2] > 0)


def test_planned_directions_reconstruct_held_out_materials_better_than_random(basis_and_held_out):
    """Measured (8 held-out tables, n = 5): mean mapped RMSE 0.33 planned against 0.55 for random
    sets (20 per material); planned sets beat about 80 % of random ones but not every one: the
    plan minimises the error expected under the basis' prior, not each material's."""
    basis, held_out = basis_and_held_out
    eta = default_eta(basis)
    n = 5
    plan = plan_directions(basis, n, candidates=5000, rng=1)
    rng = np.random.default_rng(4)
    measure = merl_entry_measure()
    scored = rng.choice(measure.size, 50_000, p=measure / measure.sum())  # averaged over pairs
    q = basis.components[:, scored].astype(np.float64)

    def error(table, wi, wo):
        entries = merl_entries(wi, wo).reshape(-1)
        c = fit_coefficients(basis, entries, table.reshape(-1)[entries], eta=eta)
        truth = basis.mapped(table)[scored]
        return float(np.sqrt(np.mean((basis.mean[scored] + c @ q - truth) ** 2)))

    planned = np.array([error(t, plan.wi, plan.wo) for t in held_out])
    random = np.array([[error(t, uniform_hemisphere_directions(rng, n, np.radians(80)),
                              uniform_hemisphere_directions(rng, n, np.radians(80))) for _ in range(20)]
                       for t in held_out])
    assert planned.mean() < 0.8 * random.mean(), (planned, random.mean(axis=1))
    assert np.mean(random < planned[:, None]) < 0.4


def test_radiance_plan_reconstructs_reflected_radiance_better(basis_and_held_out):
    """The mapped plan spends few pairs on the specular peak, where the cosine-weighted BRDF is
    largest; the radiance plan aims at that error. Measured (8 held-out tables, n = 5): relative
    cosine-weighted RMSE 0.065 (0.01-0.27 per table; the plan's linearised forecast: 0.033)
    against 0.55 for the mapped plan, whose mapped RMSE is lower (0.33 against 0.49)."""
    basis, held_out = basis_and_held_out
    eta = default_eta(basis)
    measure = merl_entry_measure()
    scored = np.random.default_rng(4).choice(measure.size, 50_000, p=measure / measure.sum())
    w = basis.cosine_weight[scored].astype(np.float64)

    def relative_error(table, plan):
        entries = merl_entries(plan.wi, plan.wo).reshape(-1)
        c = fit_coefficients(basis, entries, table.reshape(-1)[entries], eta=eta)
        f_hat, f = basis.table(c).reshape(-1)[scored], table.reshape(-1)[scored]
        return float(np.linalg.norm(w * (f_hat - f)) / np.linalg.norm(w * f))

    plans = {name: plan_directions(basis, 5, candidates=5000, rng=1, criterion=name) for name in CRITERIA}
    errors = {name: np.array([relative_error(t, plan) for t in held_out]) for name, plan in plans.items()}
    assert errors["radiance"].mean() < 0.3 * errors["mapped"].mean(), errors
    assert errors["radiance"].max() < 0.5


def test_plan_rejects_bad_input(basis_and_held_out):
    basis, _ = basis_and_held_out
    with pytest.raises(ValueError, match="eta must be > 0"):
        plan_directions(basis, 2, candidates=100, eta=0.0)
    with pytest.raises(ValueError, match="unknown criterion 'photons'"):
        plan_directions(basis, 2, candidates=100, criterion="photons")
    with pytest.raises(ValueError, match="n must lie in"):
        plan_directions(basis, 101, candidates=100)
    below = np.array([[0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match="above the horizon"):
        plan_directions(basis, 1, candidates=(below, below))
