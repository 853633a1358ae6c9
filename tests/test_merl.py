"""MERL .binary I/O and the differentiable tabulated BSDF (``abs_tabulated``)."""

from __future__ import annotations

import numpy as np
import pytest

from abs.render.variant import set_variant

set_variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from abs.errors import InputError  # noqa: E402
from abs.io.merl import (  # noqa: E402
    MERL_SCALE,
    MERL_SHAPE,
    MERL_SIZE,
    merl_sample_angles,
    read_merl,
    write_merl,
)
from abs.render.bsdfs import tabulated  # noqa: E402

# Analytic isotropic test BRDF: the φd term is weighted by sinθh·sinθd because φd is undefined
# at θh = 0 and θd = 0, where a true isotropic BRDF cannot depend on it. Its φd dependence is
# π-periodic (reciprocal) but not even, so a lookup that mirrors φd instead of folding it by π fails.
_A = np.array([0.05, 0.1, 0.2])
_B = np.array([1.0, 0.7, 0.4])
_N = 8


def analytic(theta_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray) -> np.ndarray:
    """(3, ...) BRDF values in 1/sr."""
    shape = np.cos(theta_h) ** _N * (1 + 0.3 * np.cos(theta_d))
    azimuthal = 0.4 * np.cos(2 * phi_d) + 0.3 * np.sin(2 * phi_d)
    shape = shape * (1 + np.sin(theta_h) * np.sin(theta_d) * azimuthal)
    return _A.reshape((3,) + (1,) * shape.ndim) + _B.reshape((3,) + (1,) * shape.ndim) * shape


def directions(theta_h, theta_d, phi_d, phi_h):
    """(wi, wo) as (3, M) arrays for Rusinkiewicz angles; wo is the difference vector."""
    d = np.stack([np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)])

    def to_normal_frame(v):
        x = v[0] * np.cos(theta_h) + v[2] * np.sin(theta_h)
        z = -v[0] * np.sin(theta_h) + v[2] * np.cos(theta_h)
        y = v[1]
        return np.stack([x * np.cos(phi_h) - y * np.sin(phi_h), x * np.sin(phi_h) + y * np.cos(phi_h), z])

    return to_normal_frame(np.stack([-d[0], -d[1], d[2]])), to_normal_frame(d)


def angles_of(wi: np.ndarray, wo: np.ndarray):
    """Rusinkiewicz angles from the half-vector frame (h, ∂h/∂θ, ∂h/∂φ): independent of the BSDF code."""
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=0)
    theta_h = np.arccos(np.clip(h[2], -1, 1))
    phi_h = np.arctan2(h[1], h[0])
    e_theta = np.stack([np.cos(theta_h) * np.cos(phi_h), np.cos(theta_h) * np.sin(phi_h), -np.sin(theta_h)])
    e_phi = np.stack([-np.sin(phi_h), np.cos(phi_h), np.zeros_like(phi_h)])
    dx, dy, dz = (wo * e_theta).sum(0), (wo * e_phi).sum(0), (wo * h).sum(0)
    return theta_h, np.arctan2(np.hypot(dx, dy), dz), np.arctan2(dy, dx)


def analytic_table() -> np.ndarray:
    return analytic(*merl_sample_angles()).astype(np.float32)


@pytest.fixture(scope="module")
def table() -> np.ndarray:
    return analytic_table()


@pytest.fixture(scope="module")
def bsdf(table):
    bsdf = mi.load_dict({"type": tabulated.PLUGIN_NAME})
    params = mi.traverse(bsdf)
    params[tabulated.TABLE_KEY] = mi.Float(table.ravel())
    params.update()
    return bsdf


def evaluate(bsdf, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[1])
    si.wi = mi.Vector3f(wi.astype(np.float32))
    return np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo.astype(np.float32))))


def random_upper(rng: np.random.Generator, count: int) -> np.ndarray:
    v = rng.normal(size=(3, count))
    v /= np.linalg.norm(v, axis=0)
    v[2] = np.abs(v[2]) + 1e-3
    return v / np.linalg.norm(v, axis=0)


# -- file I/O -------------------------------------------------------------------------------------
def test_write_read_roundtrip(tmp_path, table):
    path = tmp_path / "analytic.binary"
    write_merl(path, table)
    assert path.stat().st_size == 12 + 8 * MERL_SIZE
    header = np.fromfile(path, dtype="<i4", count=3)
    assert header.tolist() == [90, 90, 180]
    stored = np.fromfile(path, dtype="<f8", offset=12).reshape(MERL_SHAPE)
    np.testing.assert_allclose(stored[1] * MERL_SCALE[1], table[1], rtol=1e-6)
    back = read_merl(path)
    assert back.dtype == np.float32 and back.shape == MERL_SHAPE
    np.testing.assert_allclose(back, table, rtol=1e-6)


def test_negative_entries_read_as_zero(tmp_path, table):
    path = tmp_path / "invalid.binary"
    values = table.copy()
    values[0, 89, 89, :] = -1.0
    write_merl(path, values)
    back = read_merl(path)
    assert (back[0, 89, 89] == 0).all()
    assert back[0, 0, 0, 0] == pytest.approx(table[0, 0, 0, 0], rel=1e-6)


def test_truncated_file_names_the_file(tmp_path, table):
    path = tmp_path / "truncated.binary"
    write_merl(path, table)
    path.write_bytes(path.read_bytes()[:-8])
    with pytest.raises(InputError, match="truncated.binary") as info:
        read_merl(path)
    assert info.value.field == "data"


def test_bad_header_and_nonfinite(tmp_path, table):
    path = tmp_path / "bad.binary"
    write_merl(path, table)
    raw = bytearray(path.read_bytes())
    raw[0:4] = np.int32(45).tobytes()
    path.write_bytes(bytes(raw))
    with pytest.raises(InputError, match=r"bad\.binary: header"):
        read_merl(path)
    raw[0:4] = np.int32(90).tobytes()
    raw[12 + 8 * 1000 : 12 + 8 * 1001] = np.float64(np.nan).tobytes()
    path.write_bytes(bytes(raw))
    with pytest.raises(InputError, match=r"bad\.binary: data: 1 non-finite"):
        read_merl(path)
    with pytest.raises(InputError, match="brdf"):
        write_merl(tmp_path / "x.binary", table[:2])


# -- BSDF evaluation ------------------------------------------------------------------------------
def test_traverse_key_and_filename(tmp_path, table):
    path = tmp_path / "analytic.binary"
    write_merl(path, table)
    bsdf = mi.load_dict({"type": "abs_tabulated", "filename": str(path)})
    params = mi.traverse(bsdf)
    assert list(params.keys()) == ["table"]
    assert params.flags("table") & mi.ParamFlags.NonDifferentiable == 0
    np.testing.assert_allclose(np.array(params["table"]), table.ravel(), rtol=1e-6)
    tabulated.register()  # idempotent
    scene = mi.load_dict({"type": "scene", "mat": {"type": "abs_tabulated"}})
    assert "mat.table" in mi.traverse(scene)


def test_eval_exact_at_sample_positions(bsdf):
    rng = np.random.default_rng(1)
    count = 20000
    i, j, k = rng.integers(0, 90, count), rng.integers(0, 90, count), rng.integers(0, 180, count)
    theta_h, theta_d = (i / 90) ** 2 * (np.pi / 2), j / 90 * (np.pi / 2)
    # φd and φd + π are the same table entry (reciprocity); φh is arbitrary (isotropy).
    phi_d = k / 180 * np.pi + np.pi * rng.integers(0, 2, count)
    wi, wo = directions(theta_h, theta_d, phi_d, rng.uniform(0, 2 * np.pi, count))
    keep = (wi[2] > 1e-2) & (wo[2] > 1e-2)
    assert keep.sum() > 10000
    expected = analytic(theta_h[keep], theta_d[keep], phi_d[keep]) * wo[2, keep]
    np.testing.assert_allclose(evaluate(bsdf, wi[:, keep], wo[:, keep]), expected, rtol=2e-5)


def test_eval_interpolates_between_samples(bsdf):
    rng = np.random.default_rng(2)
    wi, wo = random_upper(rng, 20000), random_upper(rng, 20000)
    expected = analytic(*angles_of(wi, wo)) * wo[2]
    value = evaluate(bsdf, wi, wo)
    # Trilinear error of this smooth BRDF on the MERL grid is about 0.25 % at most.
    np.testing.assert_allclose(value, expected, rtol=5e-3)
    # Reciprocity: f(wi, wo) = f(wo, wi); eval carries cosθo.
    np.testing.assert_allclose(evaluate(bsdf, wo, wi) / wi[2], value / wo[2], rtol=1e-5)


def test_eval_zero_below_horizon(bsdf):
    rng = np.random.default_rng(3)
    up, down = random_upper(rng, 100), -random_upper(rng, 100)
    assert (evaluate(bsdf, up, up) > 0).all()
    assert (evaluate(bsdf, up, down) == 0).all()
    assert (evaluate(bsdf, down, up) == 0).all()


def test_sample_pdf_consistent(bsdf):
    rng = np.random.default_rng(4)
    count = 1000
    wi = random_upper(rng, count)
    si = dr.zeros(mi.SurfaceInteraction3f, count)
    si.wi = mi.Vector3f(wi.astype(np.float32))
    ctx = mi.BSDFContext()
    sample2 = mi.Point2f(rng.random((2, count)).astype(np.float32))
    bs, weight = bsdf.sample(ctx, si, mi.Float(rng.random(count).astype(np.float32)), sample2)
    value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    wo = np.array(bs.wo)
    assert (wo[2] > 0).all()
    np.testing.assert_allclose(np.array(bs.pdf), wo[2] / np.pi, rtol=1e-5)
    np.testing.assert_allclose(np.array(pdf), np.array(bs.pdf), rtol=1e-6)
    np.testing.assert_allclose(np.array(bsdf.pdf(ctx, si, bs.wo)), np.array(bs.pdf), rtol=1e-6)
    np.testing.assert_allclose(np.array(weight), np.array(value) / np.array(pdf), rtol=1e-5)


# -- gradients ------------------------------------------------------------------------------------
def test_eval_gradient_matches_finite_differences(table):
    bsdf = mi.load_dict({"type": "abs_tabulated"})
    params = mi.traverse(bsdf)
    rng = np.random.default_rng(5)
    wi, wo = random_upper(rng, 64), random_upper(rng, 64)
    weights = rng.uniform(0.5, 1.5, (3, 64))

    def scalar(values: np.ndarray) -> float:
        params["table"] = mi.Float(values)
        params.update()
        return float((evaluate(bsdf, wi, wo).astype(np.float64) * weights).sum())

    base = table.ravel().copy()
    params["table"] = mi.Float(base)
    dr.enable_grad(params["table"])
    params.update()
    si = dr.zeros(mi.SurfaceInteraction3f, 64)
    si.wi = mi.Vector3f(wi.astype(np.float32))
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo.astype(np.float32)))
    loss = dr.sum(dr.sum(value * mi.Color3f(weights.astype(np.float32))))
    dr.backward(loss)
    grad = np.array(dr.grad(params["table"]))
    dr.disable_grad(params["table"])
    touched = np.flatnonzero(grad)
    assert 0 < touched.size <= 64 * 8 * 3
    # The scalar is linear in the table, so a large step is exact up to rounding.
    step = 1.0
    for entry in list(rng.choice(touched, 6, replace=False)) + [int(np.flatnonzero(grad == 0)[0])]:
        up, down = base.copy(), base.copy()
        up[entry] += step
        down[entry] -= step
        fd = (scalar(up) - scalar(down)) / (2 * step)
        assert grad[entry] == pytest.approx(fd, rel=1e-4, abs=1e-6)


def test_render_gradient_matches_finite_differences(table):
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "prb", "max_depth": 3},
            "sensor": {
                "type": "perspective",
                "fov": 30,
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": 4},
            },
            "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
            "mat": {"type": "abs_tabulated"},
            "sphere": {"type": "sphere", "bsdf": {"type": "ref", "id": "mat"}},
        }
    )
    params = mi.traverse(scene)
    base = mi.Float(table.ravel() * 0.3)
    scale = mi.Float(1.0)
    dr.enable_grad(scale)
    params["mat.table"] = base * scale
    params.update()
    # prb retraces paths with seed_grad in its adjoint pass; a primal with that seed is the
    # exact function whose derivative it computes (the render is linear in the table here).
    image = mi.render(scene, params, seed=1, seed_grad=2)
    dr.backward(dr.sum(image, axis=None))
    ad = float(dr.grad(scale)[0])

    def render(s: float) -> float:
        params["mat.table"] = base * s
        params.update()
        return float(np.array(mi.render(scene, params, seed=2)).astype(np.float64).sum())

    step = 0.1
    fd = (render(1 + step) - render(1 - step)) / (2 * step)
    assert fd > 10.0  # the sphere covers many pixels
    assert ad == pytest.approx(fd, rel=1e-3)
