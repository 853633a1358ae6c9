"""PCA basis building (Gram-matrix PCA, leave-one-out residuals), reconstruction from a few
entries, and the direction-pair → MERL-entry conversion."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import analytic_tables

from abs.brdf.basis import BRDFBasis
from abs.brdf.directions import merl_entries, merl_entry_measure, rusinkiewicz_angles
from abs.brdf.pca import build_basis, gram_pca, loo_residuals, scaled_components
from abs.brdf.reconstruct import (
    default_eta,
    fit_coefficients,
    project_table,
    reconstruct,
)
from abs.errors import InputError
from abs.io.merl import MERL_SHAPE, MERL_SIZE, merl_sample_angles


def low_rank_data(rng, m=9, n=700, rank=4, noise=0.05):
    return (rng.normal(size=(m, rank)) @ rng.normal(size=(rank, n)) + noise * rng.normal(size=(m, n))).astype(
        np.float32)


def test_gram_pca_equals_direct_svd():
    rng = np.random.default_rng(0)
    data = low_rank_data(rng)
    original = data.astype(np.float64)
    pca = gram_pca(data, chunk=128)  # several chunks
    centred = original - original.mean(axis=0)
    np.testing.assert_allclose(data, centred, atol=1e-5)
    np.testing.assert_allclose(pca.mean, original.mean(axis=0), atol=1e-6)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    np.testing.assert_allclose(pca.singular_values[:-1], s[:-1], rtol=1e-9)
    assert pca.singular_values[-1] < 1e-6 * s[0]  # centring removes one rank
    q = scaled_components(data, pca.left, 5, chunk=100)
    # Q = VΣ up to the sign of each singular vector.
    signs = np.sign((q * (vt[:5] * s[:5, None])).sum(axis=1))
    np.testing.assert_allclose(q * signs[:, None], vt[:5] * s[:5, None], atol=2e-5 * s[0])
    # With all m − 1 components, U·Q reproduces the centred data.
    np.testing.assert_allclose(pca.left[:, :-1] @ scaled_components(data, pca.left, 8), centred, atol=1e-4)


def test_loo_residuals_match_refitting():
    rng = np.random.default_rng(1)
    data = low_rank_data(rng, m=7, n=300, rank=3).astype(np.float64)
    pca = gram_pca(data.astype(np.float32).copy())
    fast = loo_residuals(pca.gram)
    brute = np.zeros(data.shape[0] - 1)
    for j in range(data.shape[0]):
        rest = np.delete(data, j, axis=0)
        mean = rest.mean(axis=0)
        _, _, vt = np.linalg.svd(rest - mean, full_matrices=False)
        r = data[j] - mean
        for k in range(brute.size):
            brute[k] += np.sum((r - vt[:k].T @ (vt[:k] @ r)) ** 2) / data.shape[0]
    np.testing.assert_allclose(fast, brute, rtol=1e-4)
    assert fast[3] < 0.05 * fast[0]  # rank-3 data: three components explain unseen rows


# -- full-size bases from analytic tables ----------------------------------------------------------
@pytest.fixture(scope="module")
def small_basis():
    tables = analytic_tables(5)
    names = [f"m{j}" for j in range(len(tables))]
    lookup = dict(zip(names, tables))
    return build_basis(names, lookup.__getitem__, n_components=4), tables


def test_basis_reproduces_training_tables(small_basis):
    basis, tables = small_basis
    assert basis.n_components == 4 and list(basis.materials) == ["m0", "m1", "m2", "m3", "m4"]
    median = np.median(np.stack([t.ravel() for t in tables]), axis=0)
    np.testing.assert_allclose(basis.median, median, rtol=1e-6)
    valid = tables[0].ravel() > 0
    for j, table in enumerate(tables):
        # With all m − 1 components, a training table is its own coefficients' table.
        np.testing.assert_allclose(basis.table(basis.training_coefficients[j]).ravel()[valid],
                                   table.ravel()[valid], rtol=2e-3, atol=1e-5)
        np.testing.assert_allclose(project_table(basis, table), basis.training_coefficients[j], atol=1e-4)
    # The coefficients of m centred tables have variance 1/(m − 1) (rows of U); default η uses it.
    np.testing.assert_allclose(np.var(basis.training_coefficients, axis=0, ddof=1), 1 / 4, rtol=1e-5)
    assert default_eta(basis) == pytest.approx(basis.residual_variance * 4, rel=1e-5)
    assert default_eta(basis, noise=0.1) > default_eta(basis)


def test_basis_file_keeps_training_set(small_basis, tmp_path):
    basis, _ = small_basis
    basis.save(tmp_path / "basis.npz")
    loaded = BRDFBasis.load(tmp_path / "basis.npz")
    assert loaded.materials.tolist() == basis.materials.tolist()
    np.testing.assert_array_equal(loaded.training_coefficients, basis.training_coefficients)
    np.testing.assert_array_equal(loaded.singular_values, basis.singular_values)
    assert loaded.residual_variance == basis.residual_variance > 0
    arrays = dict(np.load(tmp_path / "basis.npz", allow_pickle=False))
    arrays["training_coefficients"] = arrays["training_coefficients"][:, :2]
    with open(tmp_path / "bad.npz", "wb") as file:
        np.savez(file, **arrays)
    with pytest.raises(InputError, match=r"bad\.npz: training_coefficients: expected shape \(m, 4\)"):
        BRDFBasis.load(tmp_path / "bad.npz")


def test_reconstruct_recovers_table_in_span(small_basis):
    basis, _ = small_basis
    rng = np.random.default_rng(3)
    truth_c = rng.normal(0.0, 0.5, basis.n_components)
    truth = basis.table(truth_c).ravel()
    # Entries where the truth is not clamped at 0 (the mapping is invertible there).
    unclamped = np.flatnonzero(truth > 1e-3)
    entries = rng.choice(unclamped, 12, replace=False)
    c = fit_coefficients(basis, entries, truth[entries], eta=0.0)
    np.testing.assert_allclose(c, truth_c, atol=2e-3)
    table = reconstruct(basis, entries, truth[entries], eta=0.0)
    assert table.shape == MERL_SHAPE
    np.testing.assert_allclose(table.ravel()[unclamped], truth[unclamped], rtol=5e-3, atol=1e-5)
    # The regularisation only shrinks: a large η pulls the coefficients towards 0 (the mean table).
    shrunk = fit_coefficients(basis, entries, truth[entries], eta=1e3)
    assert np.linalg.norm(shrunk) < 0.5 * np.linalg.norm(truth_c)


def test_reconstruct_rejects_bad_input(small_basis):
    basis, _ = small_basis
    with pytest.raises(ValueError, match="as many values"):
        fit_coefficients(basis, np.array([1, 2]), np.array([0.1]), eta=0.0)
    with pytest.raises(ValueError, match="entries must lie"):
        fit_coefficients(basis, np.array([MERL_SIZE]), np.array([0.1]), eta=0.0)


# -- directions → entries --------------------------------------------------------------------------
def pairs_from_angles(theta_h, theta_d, phi_d, phi_h):
    """(wi, wo) as (M, 3) arrays: d and its mirror about h, rotated to the normal frame by θh, φh."""
    d = np.stack([np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)], -1)
    mirror = d * np.array([-1.0, -1.0, 1.0])

    def to_normal_frame(v):
        x = v[:, 0] * np.cos(theta_h) + v[:, 2] * np.sin(theta_h)
        z = -v[:, 0] * np.sin(theta_h) + v[:, 2] * np.cos(theta_h)
        y = v[:, 1]
        return np.stack([x * np.cos(phi_h) - y * np.sin(phi_h), x * np.sin(phi_h) + y * np.cos(phi_h), z], -1)

    return to_normal_frame(d), to_normal_frame(mirror)


def test_merl_entries_at_sample_positions():
    rng = np.random.default_rng(4)
    count = 5000
    i, j, k = rng.integers(1, 90, count), rng.integers(1, 90, count), rng.integers(0, 180, count)
    theta_h, theta_d = (i / 90) ** 2 * (np.pi / 2), j / 90 * (np.pi / 2)
    phi_d = k / 180 * np.pi + np.pi * rng.integers(0, 2, count)  # φd and φd + π: the same entry
    # Small perturbations (well under half a bin) must not change the entry.
    jitter = rng.uniform(-0.2, 0.2, (3, count))
    theta_h = ((i + jitter[0]) / 90) ** 2 * (np.pi / 2)
    theta_d = (j + jitter[1]) / 90 * (np.pi / 2)
    phi_d = phi_d + jitter[2] / 180 * np.pi
    wi, wo = pairs_from_angles(theta_h, theta_d, phi_d, rng.uniform(0, 2 * np.pi, count))
    th, td, _ = rusinkiewicz_angles(wi, wo)
    np.testing.assert_allclose(th, theta_h, atol=1e-9)
    np.testing.assert_allclose(td, theta_d, atol=1e-9)
    expected = (i * 90 + j) * 180 + k
    entries = merl_entries(wi, wo)
    assert entries.shape == (count, 3)
    np.testing.assert_array_equal(entries[:, 0], expected)
    np.testing.assert_array_equal(entries[:, 2] - entries[:, 0], 2 * MERL_SIZE // 3)
    np.testing.assert_array_equal(merl_entries(wo, wi), entries)  # reciprocity
    # θh = 0 (mirror configuration): φh undefined, the entry still follows from θd.
    wi0, wo0 = pairs_from_angles(np.zeros(1), np.full(1, 30 / 90 * np.pi / 2), np.full(1, 0.3), np.zeros(1))
    assert merl_entries(wi0, wo0)[0, 0] // 180 == 30


def test_entry_measure_integrates_direction_pairs():
    measure = merl_entry_measure()
    third = MERL_SIZE // 3
    # All pairs of upper-hemisphere directions: (2π)² sr², to the grid's discretisation error.
    assert measure[:third].sum() == pytest.approx(4 * np.pi**2, rel=2e-3)
    # ∫∫ cosθi cosθo dωi dωo = π²: the cosine weight integrates correctly too.
    theta_h, theta_d, phi_d = (a.ravel() for a in merl_sample_angles())
    along, across = np.cos(theta_d) * np.cos(theta_h), np.sin(theta_d) * np.cos(phi_d) * np.sin(theta_h)
    assert (measure[:third] * (along + across) * (along - across)).sum() == pytest.approx(np.pi**2, rel=5e-3)
