"""The polish (abs.fitting.polish) puts a parameter whose derivative is a central difference at
the objective's own minimum, where the fit's secant slopes had their own fixed point."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
from scipy.special import ndtr

from abs import load_scene
from abs.fitting import FitSettings
from abs.fitting.objective import Objective
from abs.fitting.polish import OFFSET_FRACTION, joint_step, polish, polished_monte_carlo_covariance
from abs.model import build_model
from abs.model.parameters import ParameterVector
from abs.params.names import Parameter
from abs.simulate import simulate_capture
from conftest import make_backdrop, make_checker, make_env, make_sphere_and_floor, sphere_scene_toml

# A one-dimensional "image": three edges whose positions move non-linearly with ``t`` (as a
# checkerboard's edges seen through a lens move with its IOR), times a brightness ``a``. The
# photograph's edges are blurred more than the model's, with a slow ripple and a step the model
# lacks: a model that does not reproduce the photograph exactly, as none does.
PIXELS = np.linspace(-1.0, 1.0, 400)
EDGE_WIDTH = 0.004
STEP = 0.04  # the central differences' step: edges move by several widths over it
TRUE_T, TRUE_A = 0.1, 1.3


def _edges(t: float, width: float = EDGE_WIDTH) -> np.ndarray:
    positions = (0.3 * t, -0.5 + 0.8 * t + 2.0 * t * t, 0.6 - 0.4 * t + 1.5 * t ** 3)
    return sum(s * ndtr((PIXELS - p) / width) for p, s in zip(positions, (1.0, -0.7, 0.5)))


PHOTOGRAPH = (TRUE_A * _edges(TRUE_T, 2.5 * EDGE_WIDTH) + 0.05 * np.sin(7 * PIXELS)
              + 0.3 * ndtr((PIXELS - 0.33) / 0.01))
NOISE = 0.02  # per pixel at 1 spp; each seed's noise is common to every t (common random numbers)


def _profile_minimum() -> float:
    """The objective's minimum over ``t``, the brightness at its best for each (a dense grid)."""
    ts = np.linspace(0.09, 0.12, 6001)
    sse = []
    for t in ts:
        m = _edges(t)
        a = (m @ PHOTOGRAPH) / (m @ m)
        sse.append(float(np.sum((a * m - PHOTOGRAPH) ** 2)))
    return float(ts[int(np.argmin(sse))])


def _secant_fixed_point() -> tuple[float, float]:
    """Where Gauss-Newton with the central-difference column of step ``STEP`` stops."""
    t, a = TRUE_T, TRUE_A
    for _ in range(300):
        r = a * _edges(t) - PHOTOGRAPH
        J = np.stack([a * (_edges(t + STEP) - _edges(t - STEP)) / (2 * STEP), _edges(t)], axis=1)
        dt, da = np.linalg.lstsq(J, -r, rcond=None)[0]
        t, a = t + 0.5 * dt, a + 0.5 * da
    return t, a


@dataclass
class _Objective:
    """What :func:`polish` uses of an objective, for the edge model: ``t`` (``edge.position``)
    takes central differences, ``a`` (``light.scale``) does not."""

    vector: ParameterVector
    specs: dict
    evaluations: list = field(default_factory=list)

    @property
    def model(self):
        return type("Model", (), {"compiled": type("Compiled", (), {"specs": self.specs})()})()

    def weighted_residuals(self, z, seed, spp=1):
        t, a = self.vector.to_physical(z)
        self.evaluations.append((t, a, seed))
        noise = np.random.default_rng(seed).normal(0.0, NOISE / np.sqrt(spp), PIXELS.size)
        return a * _edges(t) + noise - PHOTOGRAPH


def _toy(t0: float, a0: float) -> _Objective:
    specs = {"edge.position": Parameter("edge.position", 1, "1", -1.0, 1.0, None, moves_paths=True,
                                        difference_step=STEP, typical_step=0.03),
             "light.scale": Parameter("light.scale", 1, "1", 0.0, float("inf"), None,
                                      reweighting="light_scale")}
    vector = ParameterVector.build(specs, ["edge.position", "light.scale"],
                                   {"edge.position": [t0], "light.scale": [a0]})
    return _Objective(vector, specs)


def _covariance(t: float, a: float) -> np.ndarray:
    """The Laplace covariance (up to the pixel variance) at ``(t, a)``: ``(J^T J)^-1`` with the
    exact derivative."""
    h = 1e-6
    J = np.stack([a * (_edges(t + h) - _edges(t - h)) / (2 * h), _edges(t)], axis=1)
    return np.linalg.inv(J.T @ J)


def test_polish_reaches_the_objectives_minimum_where_the_secant_stops_short():
    """From where the central differences' Gauss-Newton stops (0.0030 from the objective's
    minimum in ``t``, with the brightness at its best), the polish lands within a sixth of that
    gap of the minimum, with the brightness moved along the profile to its best for the new
    ``t``. Its seed pairs use common random numbers across the three offsets, and their scatter
    is its Monte-Carlo error."""
    target = _profile_minimum()
    t_fit, a_fit = _secant_fixed_point()
    gap = t_fit - target
    assert abs(gap) > 0.002, (t_fit, target)  # the secant's fixed point is not the minimum

    toy = _toy(t_fit, a_fit)
    z0 = toy.vector.to_unconstrained(toy.vector.initial)
    z, done = polish(toy, z0, spp=64, pairs=3, covariance=_covariance(t_fit, a_fit))
    t, a = toy.vector.to_physical(z)
    assert abs(t - target) < abs(gap) / 6, (t, target, t_fit)
    (entry,) = done
    assert entry.name == "edge.position" and entry.note is None
    assert entry.offset == pytest.approx(OFFSET_FRACTION * STEP)
    assert entry.start == pytest.approx(t_fit) and entry.value == pytest.approx(t)
    # Every pair rendered its three offsets with its own two seeds, the brightness held:
    # common random numbers along the scalar alone.
    seeds = {}
    for value, brightness, seed in toy.evaluations:
        assert brightness == pytest.approx(a_fit)
        seeds.setdefault(seed, set()).add(round(value - t_fit, 9))
    assert len(seeds) == 6 and all(len(offsets) == 3 for offsets in seeds.values())
    assert 0.0 < entry.monte_carlo_stderr < abs(gap) / 6
    # The brightness moved with it as the photographs correlate them, towards its best for the
    # new t (to first order: the edges are far from linear over the step).
    m = _edges(t)
    best = (m @ PHOTOGRAPH) / (m @ m)
    assert abs(a - best) < 0.5 * abs(best - a_fit), (a, best, a_fit)
    assert set(entry.slopes) == {"light.scale"} and entry.amplification > 1.0


def _step_on_quadratic(covariance, index, held, x0, m):
    """From ``x0``, the polish's step on ``f = (x - m)^T H (x - m) / 2``, ``H`` the inverse
    covariance: the exact minimum along ``index`` alone, then :func:`joint_step`."""
    H = np.linalg.inv(covariance)
    along = -(H @ (x0 - m))[index] / H[index, index]
    amplification, direction, propagation = joint_step(covariance, index, held)
    return x0 + amplification * along * direction, propagation


def test_joint_step_reaches_the_joint_minimum_of_a_quadratic():
    """From a point where the moving scalars minimise the quadratic for the polished one's value,
    the step along it alone, amplified by 1 / (1 - R^2), with the others moved by their
    regression, lands on the minimum over the moving scalars; a scalar at a bound stays where it
    is and the others' minimum is the one given it; ``propagation`` maps the start's error to
    the end's."""
    rho, s1, s2 = 0.8, 0.5, 2.0
    two = np.array([[s1 * s1, rho * s1 * s2], [rho * s1 * s2, s2 * s2]])
    amplification, direction, _ = joint_step(two, 0, np.array([False, False]))
    assert amplification == pytest.approx(1.0 / (1.0 - rho ** 2))
    np.testing.assert_allclose(direction, [1.0, rho * s2 / s1])

    rng = np.random.default_rng(3)
    A = rng.normal(size=(3, 3))
    covariance = A @ A.T + 0.3 * np.eye(3)
    H, m = np.linalg.inv(covariance), np.array([0.3, -0.2, 0.7])
    for held in ([False, False, False], [False, False, True]):
        held = np.array(held)
        moving = np.flatnonzero(~held)
        x0 = np.array([0.0, 0.0, 0.5])  # the held scalar (when one is) stays at 0.5
        # The moving others at their best for x0[0] and the held value.
        others = moving[moving != 0]
        fixed = np.setdiff1d(np.arange(3), others)
        x0[others] = m[others] - np.linalg.solve(H[np.ix_(others, others)],
                                                 H[np.ix_(others, fixed)] @ (x0[fixed] - m[fixed]))
        end, propagation = _step_on_quadratic(covariance, 0, held, x0, m)
        # The minimum over the moving scalars, the held ones where they are.
        best = x0.copy()
        best[moving] = m[moving] - np.linalg.solve(H[np.ix_(moving, moving)],
                                                   H[np.ix_(moving, np.flatnonzero(held))]
                                                   @ (x0[held] - m[held]))
        np.testing.assert_allclose(end, best, atol=1e-12)
        np.testing.assert_allclose(propagation @ (x0 - best), end - best, atol=1e-12)
    assert joint_step(None, 1, np.array([False, False]))[0] == 1.0


def test_a_pair_whose_parabola_opens_downwards_is_written_as_null():
    """fit.json is strict JSON: a non-convex pair's vertex is null, and the standard error needs
    two convex pairs."""
    import json

    from abs.fitting.polish import LinePolish

    entry = LinePolish("glass.ior", 0, 1.5, 1.501, 0.004, 64, (1.5012, float("nan")), float("nan"), {})
    text = json.dumps(entry.to_dict(), allow_nan=False)
    assert json.loads(text)["vertices"] == [1.5012, None]
    assert json.loads(text)["monte_carlo_stderr"] is None


def test_polish_keeps_the_value_and_says_so_where_the_objective_is_not_convex():
    """At a maximum of the objective along ``t`` (between two basins) the parabola opens
    downwards: the value stays and the note says why."""
    toy = _toy(0.1, 1.3)
    toy.weighted_residuals = lambda z, seed, spp=1: np.array([np.cos(40 * toy.vector.to_physical(z)[0] - 4.0)])
    covariance = _covariance(0.1, 1.3)
    z, (entry,) = polish(toy, toy.vector.to_unconstrained(toy.vector.initial), spp=64, pairs=2,
                         covariance=covariance)
    assert entry.note and "not convex" in entry.note
    np.testing.assert_allclose(toy.vector.to_physical(z), [0.1, 1.3])
    # Nothing moved, so the optimiser's Monte-Carlo error stands.
    assert entry.slopes == {} and not np.isfinite(entry.monte_carlo_stderr)
    extra = np.array([[4e-6, 1e-6], [1e-6, 9e-6]])
    np.testing.assert_array_equal(polished_monte_carlo_covariance(extra, toy.vector, [entry]), extra)


def test_polished_covariance_replaces_the_scalars_monte_carlo_share():
    """The polished scalar's Monte-Carlo variance is the polish's, carried along the profile's
    slopes; the other scalars keep their own."""
    toy = _toy(0.1, 1.3)
    from abs.fitting.polish import LinePolish

    entry = LinePolish("edge.position", 0, 0.1, 0.099, 0.008, 64, (0.0989, 0.0991), 1e-4,
                       {"light.scale": [2.0]}, 1.1)  # no propagation: the row is replaced
    extra = np.array([[4e-6, 1e-6], [1e-6, 9e-6]])
    out = polished_monte_carlo_covariance(extra, toy.vector, [entry])
    np.testing.assert_allclose(out, [[1e-8, 2e-8], [2e-8, 9e-6 + 4e-8]])


@pytest.mark.slow
def test_polish_on_glass_before_a_checkerboard_lands_at_the_true_ior(tmp_path):
    """On photographs abs rendered (the model exact), the objective's minimum in IOR is the truth:
    the polish from 0.005 off lands within 0.0015 of it (the absorption and scale held at their
    truths)."""
    make_sphere_and_floor(tmp_path)
    make_backdrop(tmp_path)
    make_env(tmp_path / "env.exr")
    make_checker(tmp_path / "checker.png")
    fitted = ["glass.absorption", "glass.ior", "environment.scale"]
    text = sphere_scene_toml(fitted, absorption=[6.0, 2.5, 1.0])
    (tmp_path / "truth.toml").write_text(text.replace("ior = [1.5, 1.5, 1.5]", "ior = [1.52, 1.52, 1.52]"))
    (tmp_path / "start.toml").write_text(text.replace("ior = [1.5, 1.5, 1.5]", "ior = [1.524, 1.524, 1.524]"))
    simulate_capture(load_scene(tmp_path / "truth.toml"), tmp_path / "capture", n_cameras=2,
                     width=64, height=48, spp=1024, shot_noise=1e-4, read_noise=0.002, seed=2)
    settings = FitSettings(spp=16, tie=("glass.ior",), glass_spp_factor=4)
    model = build_model(tmp_path / "start.toml", tmp_path / "capture", fitted, tied=settings.tie,
                        glass_spp_factor=4)
    objective = Objective.build(model, settings, sigma=0.01, priors={})
    z0 = model.vector.to_unconstrained(model.vector.initial)
    z, (entry,) = polish(objective, z0, spp=512, pairs=2, steps={"glass.ior": 0.04})
    ior = model.vector.split(model.vector.to_physical(z))["glass.ior"][0]
    assert entry.note is None and entry.offset == pytest.approx(0.008)
    assert abs(ior - 1.52) < 0.0015, entry
    assert entry.slopes == {} and entry.monte_carlo_stderr < 0.0015
