"""PCA BRDF basis: mapping, file format and the differentiable table reconstruction."""

from __future__ import annotations

import numpy as np
import pytest

from abs.render.variant import set_variant

set_variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from abs.brdf.basis import (  # noqa: E402
    COSINE_WEIGHT_MIN,
    BRDFBasis,
    map_brdf,
    merl_cosine_weight,
    unmap_brdf,
)
from abs.errors import InputError  # noqa: E402
from abs.io.merl import MERL_SIZE  # noqa: E402
from abs.render.brdf_tables import table_from_coefficients  # noqa: E402

EPS = 1e-3
K = 3


@pytest.fixture(scope="module")
def basis() -> BRDFBasis:
    rng = np.random.default_rng(0)
    median = rng.uniform(0.0, 2.0, MERL_SIZE).astype(np.float32)
    mean = rng.normal(0.0, 0.3, MERL_SIZE).astype(np.float32)
    components = rng.normal(0.0, 0.2, (K, MERL_SIZE)).astype(np.float32)
    return BRDFBasis(mean=mean, components=components, median=median, epsilon=EPS)


def test_cosine_weight():
    w = merl_cosine_weight()
    assert w.shape == (MERL_SIZE,)
    assert w.min() == pytest.approx(COSINE_WEIGHT_MIN)
    # Entry (θh=0, θd=0): both directions along the normal.
    assert w[0] == pytest.approx(1.0)
    # Same weight for R, G, B.
    third = MERL_SIZE // 3
    assert np.array_equal(w[:third], w[third : 2 * third])
    # θh = 0, θd = j·π/180: cosθi·cosθo = cos²θd for every φd.
    j = 30
    np.testing.assert_allclose(w[j * 180 : (j + 1) * 180], np.cos(j / 90 * np.pi / 2) ** 2, rtol=1e-6)


def test_map_unmap_are_inverses():
    rng = np.random.default_rng(1)
    f = rng.lognormal(-2.0, 2.0, 10000)
    f[:10] = 0.0
    median = rng.lognormal(-2.0, 1.0, 10000)
    w = rng.uniform(COSINE_WEIGHT_MIN, 1.0, 10000)
    x = map_brdf(f, median, w, EPS)
    np.testing.assert_allclose(map_brdf(median, median, w, EPS), 0.0, atol=1e-15)
    np.testing.assert_allclose(unmap_brdf(x, median, w, EPS), f, rtol=1e-12, atol=1e-15)
    y = rng.normal(0.0, 1.0, 10000)
    np.testing.assert_allclose(map_brdf(unmap_brdf(y, median, w, EPS), median, w, EPS), y, rtol=1e-9, atol=1e-9)


def test_save_load_roundtrip(tmp_path, basis):
    path = tmp_path / "basis.npz"
    basis.save(path)
    assert path.exists()
    loaded = BRDFBasis.load(path)
    assert loaded.n_components == K
    assert loaded.epsilon == EPS
    assert loaded.source == str(path)
    for name in ("mean", "components", "median", "cosine_weight"):
        assert np.array_equal(getattr(loaded, name), getattr(basis, name)), name


def write_npz(path, **arrays):
    with open(path, "wb") as file:
        np.savez(file, **arrays)


def test_load_refuses_pickles_and_bad_arrays(tmp_path, basis):
    good = dict(
        mean=basis.mean,
        components=basis.components,
        median=basis.median,
        epsilon=np.float64(EPS),
        format_version=np.int64(1),
    )
    path = tmp_path / "evil.npz"
    write_npz(path, **{**good, "mean": np.array([{"payload": 1}], dtype=object)})
    with pytest.raises(InputError, match=r"evil\.npz: mean: cannot be loaded without unpickling"):
        BRDFBasis.load(path)

    path = tmp_path / "short.npz"
    write_npz(path, **{**good, "components": basis.components[:, :-1]})
    with pytest.raises(InputError, match=r"short\.npz: components: expected shape"):
        BRDFBasis.load(path)

    path = tmp_path / "missing.npz"
    write_npz(path, **{k: v for k, v in good.items() if k != "median"})
    with pytest.raises(InputError, match=r"missing\.npz: median: missing"):
        BRDFBasis.load(path)

    path = tmp_path / "version.npz"
    write_npz(path, **{**good, "format_version": np.int64(2)})
    with pytest.raises(InputError, match=r"version\.npz: format_version"):
        BRDFBasis.load(path)

    path = tmp_path / "notzip.npz"
    path.write_bytes(b"not an archive")
    with pytest.raises(InputError, match=r"notzip\.npz"):
        BRDFBasis.load(path)


def test_table_matches_numpy(basis):
    c = np.array([0.5, -1.0, 2.0], dtype=np.float32)
    table = np.array(table_from_coefficients(basis, mi.Float(c)))
    x = basis.mean.astype(np.float64) + c.astype(np.float64) @ basis.components.astype(np.float64)
    w = basis.cosine_weight.astype(np.float64)
    expected = np.maximum(unmap_brdf(x, basis.median, w, EPS), 0.0)
    assert (expected == 0).any() and (expected > 0).any()
    np.testing.assert_allclose(table, expected, rtol=2e-4, atol=1e-5)


def test_table_gradient_matches_finite_differences(basis):
    rng = np.random.default_rng(2)
    c0 = np.array([0.3, -0.2, 0.5], dtype=np.float64)
    # Entries well away from the clamp at f = 0, where the central difference would straddle a kink.
    start = np.array(table_from_coefficients(basis, mi.Float(c0.astype(np.float32))))
    entries = rng.choice(np.flatnonzero(start > 0.2), 2000, replace=False)
    weights = rng.uniform(0.5, 1.5, entries.size)

    def scalar(c: np.ndarray) -> float:
        table = np.array(table_from_coefficients(basis, mi.Float(c.astype(np.float32))))
        return float((table[entries].astype(np.float64) * weights).sum())

    coefficients = mi.Float(c0.astype(np.float32))
    dr.enable_grad(coefficients)
    table = table_from_coefficients(basis, coefficients)
    picked = dr.gather(mi.Float, table, mi.UInt32(entries.astype(np.uint32)))
    loss = dr.sum(picked * mi.Float(weights.astype(np.float32)))
    dr.backward(loss)
    grad = np.array(dr.grad(coefficients))
    step = 1e-2
    for k in range(K):
        e = np.zeros(K)
        e[k] = step
        fd = (scalar(c0 + e) - scalar(c0 - e)) / (2 * step)
        assert abs(fd) > 1.0
        assert grad[k] == pytest.approx(fd, rel=2e-4)


def test_wrong_coefficient_count(basis):
    with pytest.raises(ValueError, match="expected 3 coefficients"):
        table_from_coefficients(basis, mi.Float([1.0, 2.0]))
