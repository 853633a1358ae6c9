"""Posterior sampling without the renderer: closed-form posteriors, the crossed likelihood's
bias, resuming a chain file.

The sampler takes any log-posterior, so a linear-Gaussian stand-in for the renderer
(``r = A theta - y`` with known noise) has a posterior known in closed form.
"""

from __future__ import annotations

import emcee
import numpy as np
import pytest

from abs.sampling.checks import run_checks
from abs.sampling.ensemble import run_ensemble
from abs.sampling.likelihood import crossed_log_likelihood, gaussian_log_likelihood
from abs.sampling.posterior import LogPrior, ResidualPosterior
from abs.sampling.summary import burn_in, parameter_summary

SIGMA = 0.2


def _linear_problem(seed: int = 1, m: int = 40):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, 3)) * [1.0, 0.5, 2.0]
    A[:, 1] += 0.6 * A[:, 0]  # correlated parameters
    truth = np.array([1.0, -0.5, 2.0])
    y = A @ truth + SIGMA * rng.normal(size=m)
    return A, y


def _wide_prior(p: int) -> LogPrior:
    return LogPrior(np.full(p, -50.0), np.full(p, 50.0))


def _run(posterior, start, tmp_path=None, steps=3000, seed=0, **kw):
    """The chain in an HDF5 file under ``tmp_path``, or in memory without one (faster)."""
    backend = (emcee.backends.HDFBackend(str(tmp_path / "chain.h5")) if tmp_path
               else emcee.backends.Backend())
    rng = np.random.default_rng(seed)
    initial = start + 1e-2 * rng.normal(size=(16, start.size))
    progress = run_ensemble(posterior, backend, initial, max_steps=steps, seed=seed, **kw)
    return backend, progress


def _check_against(backend, progress, mean, cov):
    """Sampler mean within 4 Monte-Carlo standard errors; sds within 12 %, correlations 0.08."""
    chain = backend.get_chain(discard=burn_in(progress.tau, progress.steps))
    s = parameter_summary(chain, ["x"], [mean.size], ["1"], progress.tau)["x"]
    sd = np.sqrt(np.diag(cov))
    err = np.abs(np.array(s["mean"]) - mean) / (sd / np.sqrt(s["ess"]))
    assert np.all(err < 4.0), (s["mean"], mean, err)
    assert np.allclose(s["sd"], sd, rtol=0.12), (s["sd"], sd)
    flat = chain.reshape(-1, mean.size)
    corr, true_corr = np.corrcoef(flat.T), cov / np.outer(sd, sd)
    assert np.allclose(corr, true_corr, atol=0.08), (corr, true_corr)


def test_linear_gaussian_posterior_matches_closed_form():
    A, y = _linear_problem()
    posterior = ResidualPosterior(lambda t: [A @ t - y], SIGMA ** 2, _wide_prior(3))
    cov = SIGMA ** 2 * np.linalg.inv(A.T @ A)
    mean = cov @ A.T @ y / SIGMA ** 2
    backend, progress = _run(posterior, mean, check_every=50)
    assert progress.converged and progress.stop_reason == "converged"
    assert 0.2 < progress.acceptance_fraction < 0.9
    _check_against(backend, progress, mean, cov)


def test_crossed_likelihood_posterior_matches_closed_form():
    """Two fixed-noise evaluations ``r_a, r_b``: the crossed likelihood's posterior is centred on
    the average evaluation with the variance of the average."""
    A, y = _linear_problem(seed=2)
    rng = np.random.default_rng(3)
    e_a, e_b = 0.3 * rng.normal(size=(2, y.size))  # fixed render noise of the two seeds
    variance = SIGMA ** 2 + 0.3 ** 2 / 2
    posterior = ResidualPosterior(lambda t: [A @ t + e_a - y, A @ t + e_b - y], variance,
                                  _wide_prior(3))
    cov = variance * np.linalg.inv(A.T @ A)
    mean = cov @ A.T @ (y - (e_a + e_b) / 2) / variance
    backend, progress = _run(posterior, mean, seed=4, check_every=50)
    _check_against(backend, progress, mean, cov)


class _LinearRenderPosterior:
    """A stand-in for RenderPosterior: ``r_s = A theta + e_s - y`` for two fixed seeds, with the
    attributes :func:`abs.sampling.mode.find_mode` reads."""

    spp, seeds, prior = 1, (1, 2), _wide_prior(3)

    def __init__(self, A, y, noise, variance):
        self.A, self.y, self.noise, self.variance = A, y, noise, variance

    def problem(self):
        return self

    def jacobian(self, theta, spp, seed):
        return self.A

    def residuals(self, theta, spp=None, seed=None):
        if seed is not None:  # FitProblem.residuals: (r, J) of a render seeded ``seed``
            return self.A @ theta + self.noise(seed) - self.y, None
        return [self.A @ theta + self.noise(s) - self.y for s in self.seeds]

    def __call__(self, theta):
        return ResidualPosterior(self.residuals, self.variance, self.prior)(theta)


def test_find_mode_reaches_the_crossed_likelihoods_maximum():
    """Gauss-Newton from a start 30 standard deviations away lands on the closed-form maximum of
    the crossed likelihood (the average evaluation's least squares) with its Laplace sd."""
    from abs.sampling.mode import find_mode

    A, y = _linear_problem(seed=5)
    rng = np.random.default_rng(6)
    fixed = {1: 0.3 * rng.normal(size=y.size), 2: 0.3 * rng.normal(size=y.size)}
    noise = fixed.__getitem__
    variance = np.full(y.size, SIGMA ** 2 + 0.3 ** 2 / 2)
    cov = np.linalg.inv(A.T @ (A / variance[:, None]))
    mode = cov @ A.T @ ((y - (fixed[1] + fixed[2]) / 2) / variance)
    start = mode + 30 * np.sqrt(np.diag(cov))
    theta, sd = find_mode(_LinearRenderPosterior(A, y, noise, variance), start,
                          np.full(3, -50.0), np.full(3, 50.0))
    np.testing.assert_allclose(theta, mode, atol=1e-6)
    np.testing.assert_allclose(sd, np.sqrt(np.diag(cov)), rtol=1e-9)
    # Bounds hold: with the upper bound below the mode, the start stays inside it.
    upper = mode - 0.1
    theta, _ = find_mode(_LinearRenderPosterior(A, y, noise, variance), mode - 1.0,
                         np.full(3, -50.0), upper)
    assert np.all(theta < upper)


@pytest.mark.parametrize("true_ratio", [1.0, 4.0])
def test_seed_pair_calibration_measures_and_recentres(true_ratio):
    """Render noise whose real variance is ``true_ratio`` times the modelled one: the measured
    ratio finds it, the scale is never below 1, and the offset makes the chain pair's residuals
    those of the average over all pairs."""
    from abs.sampling.calibration import calibrate_render_noise

    A, y = _linear_problem(seed=7)
    modelled = np.full(y.size, 0.3 ** 2)  # var_render / 2 the noise model believes

    def noise(seed):  # each render's own noise, variance true_ratio * 2 * modelled
        return np.sqrt(true_ratio * 2 * modelled) * np.random.default_rng(seed).normal(size=y.size)

    posterior = _LinearRenderPosterior(A, y, noise, modelled + SIGMA ** 2)
    theta = np.zeros(3)
    found = calibrate_render_noise(posterior, theta, modelled, pairs=400, seed=100)
    np.testing.assert_allclose(found.ratio, true_ratio, rtol=0.2)
    assert found.scale >= 1.0 and found.scale == pytest.approx(max(1.0, found.ratio.max()))
    every = [noise(s) for s in (1, 2, *range(100, 900))]
    # A parameter the photographs do not see (a zero column) gets no ratio, not a failure.
    blind = _LinearRenderPosterior(np.column_stack([A, np.zeros(y.size)]), y, noise,
                                   modelled + SIGMA ** 2)
    partial = calibrate_render_noise(blind, np.zeros(4), modelled, pairs=50, seed=100)
    assert np.isnan(partial.ratio[3]) and np.isfinite(partial.ratio[:3]).all() and partial.scale >= 1
    recentred = [r + o for r, o in zip(posterior.residuals(theta), found.offset)]
    np.testing.assert_allclose(np.mean(recentred, axis=0), A @ theta + np.mean(every, axis=0) - y,
                               atol=1e-12)


class _ScaleRenderPosterior(_LinearRenderPosterior):
    """A stand-in whose render noise grows with the parameter, as an environment scale's or a
    clear glass's does: ``r_s = theta (a + e_s) - y``, and the Jacobian ``a + e_s`` carries the
    same render's noise (a bright path raises a pixel and its derivative alike)."""

    prior = _wide_prior(1)

    def __init__(self, a, y, noise, variance, offset=None):
        super().__init__(a[:, None], y, noise, variance)
        self.a, self.offset = a, offset

    def jacobian(self, theta, spp, seed):
        return (self.a + self.noise(seed))[:, None]

    def residuals(self, theta, spp=None, seed=None):
        if seed is not None:
            return theta[0] * (self.a + self.noise(seed)) - self.y, None
        shifts = (0.0, 0.0) if self.offset is None else self.offset
        return [theta[0] * (self.a + self.noise(s)) - self.y + o for s, o in zip(self.seeds, shifts)]


def test_recentring_leaves_the_mode_unbiased_when_noise_grows_with_the_parameter():
    """Over many noise draws the recentred chain's mode averages to the truth. The former offset,
    shared by both renders, put each render's own noise into its crossed product and biased the
    mode towards noisier renderings (brighter scale, clearer glass: SBC posteriors half an sd off);
    it is kept here as the control that shows the test can tell."""
    from abs.sampling.calibration import calibrate_render_noise
    from abs.sampling.mode import find_mode

    rng = np.random.default_rng(11)
    a = rng.uniform(0.5, 1.0, size=60)
    truth, rel = 2.0, 0.3
    y = truth * a  # noise-free photograph: any bias is the render noise's
    render_part = (truth * rel * a) ** 2 / 2
    bounds = np.array([0.1]), np.array([10.0])
    new, old = [], []
    for rep in range(150):
        def noise(seed, rep=rep):
            return rel * a * np.random.default_rng(1000 * rep + seed).normal(size=a.size)

        posterior = _ScaleRenderPosterior(a, y, noise, render_part)
        theta0, _ = find_mode(posterior, np.array([truth]), *bounds)
        found = calibrate_render_noise(posterior, theta0, render_part, pairs=8, seed=100)
        for offset, out in ((found.offset, new), (np.repeat(found.offset.mean(0, keepdims=True), 2, 0), old)):
            recentred = _ScaleRenderPosterior(a, y, noise, render_part / 9, offset)
            out.append(find_mode(recentred, theta0, *bounds, tolerance=1e-4)[0][0] - truth)
    new, old = np.array(new), np.array(old)
    se = new.std() / np.sqrt(new.size)
    assert abs(new.mean()) < 3 * se, (new.mean(), se)
    assert old.mean() > 10 * se, (old.mean(), se)  # the shared offset's bias, for contrast
    # The recentred mode scatters as the least squares of the average of all 9 pairs would.
    assert new.std() == pytest.approx(truth * rel / np.sqrt(2 * 9 * a.size), rel=0.25)


def test_bounds_and_priors():
    prior = LogPrior(np.array([0.0, 1.0]), np.array([np.inf, 3.0]), np.array([0.0, 1.5]),
                     np.array([np.inf, 0.1]))
    assert prior(np.array([-1e-9, 1.5])) == -np.inf and prior(np.array([1.0, 3.0])) == -np.inf
    assert prior(np.array([7.0, 1.7])) == pytest.approx(-0.5 * 4.0)


def test_crossed_likelihood_removes_the_noise_energy_bias():
    """A render whose noise scales with the parameter (``s (f + e)``, like an environment scale):
    the plain Gaussian likelihood peaks low by ``|e|^2 / (|f|^2 + |e|^2)`` (errors in variables),
    the crossed one does not."""
    rng = np.random.default_rng(5)
    f = rng.uniform(0.2, 1.0, size=200)
    grid = np.linspace(0.6, 1.4, 801)
    plain, crossed = [], []
    for _ in range(200):
        y = f + 0.01 * rng.normal(size=f.size)
        e_a, e_b = 0.5 * f * rng.normal(size=(2, f.size))  # render noise: 50 % per pixel
        plain.append(grid[np.argmax([gaussian_log_likelihood(s * (f + e_a) - y, 1.0) for s in grid])])
        crossed.append(grid[np.argmax([crossed_log_likelihood(s * (f + e_a) - y, s * (f + e_b) - y, 1.0)
                                       for s in grid])])
    plain, crossed = np.array(plain), np.array(crossed)
    se = crossed.std() / np.sqrt(crossed.size)
    assert plain.mean() < 1.0 - 0.15  # the expected bias: 1 / (1 + 0.25) = 0.8
    assert abs(crossed.mean() - 1.0) < 4 * se + 1e-3


def test_an_interrupted_chain_resumes_from_its_file(tmp_path):
    A, y = _linear_problem()
    posterior = ResidualPosterior(lambda t: [A @ t - y], SIGMA ** 2, _wide_prior(3))
    start = np.linalg.lstsq(A, y, rcond=None)[0]

    class Stop(Exception):
        pass

    def interrupt(progress):
        if progress.steps == 30:
            raise Stop

    with pytest.raises(Stop):
        _run(posterior, start, tmp_path, steps=200, on_step=interrupt)
    first = emcee.backends.HDFBackend(str(tmp_path / "chain.h5"), read_only=True).get_chain()
    assert first.shape == (30, 16, 3)
    seen = []
    backend, progress = _run(posterior, start + 5.0, tmp_path, steps=60,  # start is ignored
                             on_step=seen.append)
    chain = backend.get_chain()
    assert progress.steps == 60 and chain.shape == (60, 16, 3)
    # Reports count the file's steps, the first one step after the resumed 30; the budget is
    # the file's length when the run ends (what a progress bar fills to).
    assert seen[0].steps == 31 and {p.budget_steps for p in seen} == {60}
    np.testing.assert_array_equal(chain[:30], first)
    # The continuation moves from the saved walkers, not from the (far away) new start.
    assert np.abs(chain[30:] - start).max() < 3.0
    # Budgets count the whole file: nothing more to do at the same max_steps.
    assert _run(posterior, start, tmp_path, steps=60)[1].stop_reason == "max_steps"


def test_independence_sampler_matches_closed_form():
    """The Laplace-proposal alternative on the linear stand-in (where Laplace is exact up to the
    proposal's scale): mean within 4 Monte-Carlo errors, sds within 10 %."""
    from emcee.autocorr import integrated_time

    from abs.sampling.independence import independence_sampler

    A, y = _linear_problem(seed=6)
    posterior = ResidualPosterior(lambda t: [A @ t - y], SIGMA ** 2, _wide_prior(3))
    cov = SIGMA ** 2 * np.linalg.inv(A.T @ A)
    mean = cov @ A.T @ y / SIGMA ** 2
    # A Laplace centre slightly off (as a fit's would be) costs acceptance, not correctness.
    run = independence_sampler(posterior, mean + 0.2 * np.sqrt(np.diag(cov)), cov, 6000, seed=1)
    assert run.acceptance_fraction > 0.3
    chain = run.chain[100:]
    ess = chain.shape[0] / integrated_time(chain[:, None, :], quiet=True)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(chain.mean(axis=0) - mean) < 4 * sd / np.sqrt(ess))
    assert np.allclose(chain.std(axis=0), sd, rtol=0.1)


def test_adapted_independence_sampler_recovers_skewed_posterior():
    """A bounded, skewed posterior (independent gammas) and a poor Laplace proposal (centred 1.5
    sd low, 3x too narrow), as on the glass scene: unadapted, the chain sticks; adapted by
    importance sampling, it recovers the known means and sds."""
    from emcee.autocorr import integrated_time

    from abs.sampling.independence import independence_sampler

    shape, scale = np.array([2.5, 4.0, 8.0]), np.array([1.0, 1.2, 0.8])
    true_mean, true_sd = shape * scale, np.sqrt(shape) * scale

    def log_prob(t):
        return float(np.sum((shape - 1) * np.log(t) - t / scale)) if np.all(t > 0) else -np.inf

    start, cov = np.maximum(true_mean - 1.5 * true_sd, 0.3), np.diag((true_sd / 3) ** 2)
    stuck = independence_sampler(log_prob, start, cov, 1500, seed=4)
    assert stuck.acceptance_fraction < 0.1
    run = independence_sampler(log_prob, start, cov, 4000, adapt_evaluations=300, seed=4)
    assert run.acceptance_fraction > 0.25 and run.evaluations == 4300
    ess = run.chain.shape[0] / integrated_time(run.chain[:, None, :], quiet=True)
    assert np.all(np.abs(run.chain.mean(axis=0) - true_mean) < 4 * true_sd / np.sqrt(ess))
    assert np.allclose(run.chain.std(axis=0), true_sd, rtol=0.2)


def test_checks_warn_of_a_too_narrow_noise_model_and_an_unfinished_chain():
    done = {"noise": {"reduced_chi2_at_mode": 1.02}, "converged": True, "stop_reason": "converged"}
    assert run_checks(done) == []
    [narrow] = run_checks({**done, "noise": {"reduced_chi2_at_mode": 1.69}})
    assert "1.69 times" in narrow and "1.30x" in narrow  # intervals too narrow by sqrt(chi^2)
    [short] = run_checks({**done, "converged": False, "stop_reason": "max_evaluations", "steps": 3})
    assert "max_evaluations" in short and "3 steps" in short


def test_noise_correlation_widens_the_likelihood_of_correlated_views():
    """A built capture's view (pixels whose noise demosaicing spread) has its variances multiplied
    per channel by its correlation factors; an ordinary view keeps them."""
    from abs.sampling.likelihood import NoiseModel

    masks = [np.ones((2, 2), bool), np.ones((1, 3), bool)]
    render = [np.full((2, 2, 3), 0.02), np.full((1, 3, 3), 0.04)]
    plain = NoiseModel(np.array([0.01, 0.03]), render)
    built = NoiseModel(np.array([0.01, 0.03]), render,
                       correlation=np.array([[7.9, 3.9, 7.9], [1.0, 1.0, 1.0]]))
    a, b = plain.residual_variance(masks), built.residual_variance(masks)
    np.testing.assert_allclose(b[:12].reshape(4, 3) / a[:12].reshape(4, 3), [[7.9, 3.9, 7.9]] * 4)
    np.testing.assert_allclose(b[12:], a[12:])
    assert built.to_dict()["noise_correlation"][0] == [7.9, 3.9, 7.9]
