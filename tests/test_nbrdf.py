"""Neural MERL fits (shared data): weights, the network formula, tables, cache, and the MERL
.binary path giving the same tables."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from abs.brdf.directions import rusinkiewicz_angles
from abs.brdf.measured import STUDY_MATERIALS, measured_material_names, measured_table
from abs.brdf.nbrdf import (
    evaluate_nbrdf,
    nbrdf_archive_path,
    nbrdf_material_names,
    nbrdf_table,
    nbrdf_weights,
)
from abs.errors import InputError
from abs.io.merl import MERL_SHAPE, merl_sample_angles, write_merl

pytestmark = pytest.mark.skipif(not nbrdf_archive_path().is_file(),
                                reason=f"shared data missing: {nbrdf_archive_path()} (see ../shared/README.md)")


def direct_network(name: str, theta_h, theta_d, phi_d) -> np.ndarray:
    """FORMAT.md items 3-9 written out independently, in float64: h5py straight from the zip."""
    import h5py

    with zipfile.ZipFile(nbrdf_archive_path()) as zf:
        raw = zf.read(f"merl_nbrdf/{name}.h5")
    with h5py.File(io.BytesIO(raw), "r") as h5:
        w = [np.asarray(h5[f"dense_{k}/dense_{k}/kernel:0"], np.float64) for k in (1, 2, 3)]
        b = [np.asarray(h5[f"dense_{k}/dense_{k}/bias:0"], np.float64) for k in (1, 2, 3)]
    x = np.stack([np.sin(theta_h), 0 * theta_h, np.cos(theta_h), np.sin(theta_d) * np.cos(phi_d),
                  np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)], axis=-1)
    y = np.maximum(x @ w[0] + b[0], 0)
    y = np.maximum(y @ w[1] + b[1], 0)
    return np.maximum(np.exp(y @ w[2] + b[2]) - 1, 0)


def test_names_and_weights():
    names = nbrdf_material_names()
    assert len(names) == 95 and set(STUDY_MATERIALS) <= set(names)
    assert measured_material_names() == names
    weights = nbrdf_weights("blue-rubber")
    assert [k.shape for k in weights.kernels] == [(6, 21), (21, 21), (21, 3)]
    assert sum(k.size for k in weights.kernels) + sum(b.size for b in weights.biases) == 675
    with pytest.raises(InputError, match=r"merl_nbrdf\.zip: no-such-paint: no such material"):
        nbrdf_weights("no-such-paint")


def test_table_matches_direct_network(tmp_path, monkeypatch):
    monkeypatch.setenv("ABS_CACHE", str(tmp_path))
    name = "green-metallic-paint"
    table = nbrdf_table(name)
    assert table.shape == MERL_SHAPE and table.dtype == np.float32
    cached = list((tmp_path / "merl").glob(f"{name}-*.npy"))
    assert len(cached) == 1
    np.testing.assert_array_equal(nbrdf_table(name), table)  # from the cache
    theta_h, theta_d, phi_d = merl_sample_angles()
    rng = np.random.default_rng(0)
    i, j, k = rng.integers(0, 90, 3000), rng.integers(0, 90, 3000), rng.integers(0, 180, 3000)
    th, td, pd = theta_h[i, j, k], theta_d[i, j, k], phi_d[i, j, k]
    # Each entry: mean of the network at φd and φd + π (reciprocal), 0 below the horizon.
    expected = 0.5 * (direct_network(name, th, td, pd) + direct_network(name, th, td, pd + np.pi))
    along, across = np.cos(td) * np.cos(th), np.sin(td) * np.cos(pd) * np.sin(th)
    below = (along + across <= 0) | (along - across <= 0)
    expected[below] = 0
    assert 0.05 < below.mean() < 0.5
    np.testing.assert_allclose(table[:, i, j, k].T, expected, rtol=1e-4, atol=1e-7)


def test_normal_incidence_albedo_range():
    """FORMAT.md: normal-incidence albedos lie between 0.004 (black-obsidian) and 0.44 (orange-paint)."""
    # Viewing along the normal the configuration is symmetric about it, so f depends on the light's
    # polar angle θ only: albedo = 2π ∫ f(θ) cosθ sinθ dθ, integrated on a grid dense near the
    # specular peak at θ = 0 (θ = t²·π/2).
    t = np.linspace(0.0, 1.0, 20001)
    theta = t**2 * (np.pi / 2)
    wi = np.stack([np.sin(theta), 0 * theta, np.cos(theta)], -1)
    angles = rusinkiewicz_angles(wi, np.tile([0.0, 0.0, 1.0], (theta.size, 1)))
    jacobian = 2 * np.pi * np.cos(theta) * np.sin(theta) * t * np.pi  # dθ/dt = t·π
    albedo = {name: np.trapezoid(evaluate_nbrdf(nbrdf_weights(name), *angles) * jacobian[:, None], t, axis=0)
              for name in ("black-obsidian", "orange-paint", "blue-rubber", "gold-metallic-paint")}
    assert albedo["black-obsidian"].min() == pytest.approx(0.004, abs=5e-4)
    assert albedo["orange-paint"].max() == pytest.approx(0.44, abs=0.01)
    for value in albedo.values():
        assert (value > 0.0035).all() and (value < 0.45).all()


def test_merl_binary_gives_the_same_table(tmp_path):
    """The .binary reader path: a table written as a MERL file reads back as the same table."""
    name = "purple-paint"
    table = nbrdf_table(name)
    write_merl(tmp_path / f"{name}.binary", table)
    assert measured_material_names(tmp_path) == [name]
    np.testing.assert_allclose(measured_table(name, tmp_path), table, rtol=1e-6, atol=0)
    with pytest.raises(InputError, match="no MERL file"):
        measured_table("blue-rubber", tmp_path)
