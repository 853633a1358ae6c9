"""A failing fit says so: the checks read the signs of failure from the fit's own numbers."""

from __future__ import annotations

import numpy as np

from abs.fitting.checks import run_checks

BOUNDS = {"glass.ior": (1.0, 3.0), "glass.absorption": (0.0, np.inf), "environment.scale": (0.0, np.inf)}
KINDS = {"glass.ior": ("dielectric", "ior"), "glass.absorption": ("dielectric", "absorption")}


def _summary(**changes):
    summary = {
        "parameters": {
            "glass.ior": {"value": [1.52, 1.525, 1.53], "stderr": [0.002, 0.002, 0.003]},
            "glass.absorption": {"value": [6.1, 2.4, 1.1], "stderr": [0.3, 0.2, 0.2]},
            "environment.scale": {"value": [1.6], "stderr": [0.01]},
        },
        "correlation": {"names": ["a", "b"], "matrix": [[1.0, 0.4], [0.4, 1.0]]},
        "holdout_rmse": {"before": 0.27, "after": 0.021},
        "image_noise": 0.012,
    }
    summary.update(changes)
    return summary


def test_a_good_fit_raises_no_check():
    assert run_checks(_summary(), BOUNDS, KINDS) == []


def test_the_failed_glass_fit_of_the_issue_announces_itself():
    """The fit that returned IOR 2.18 for 1.523, five unconstrained scalars and a holdout RMSE of
    0.143: every sign is named."""
    summary = _summary(parameters={
        "glass.ior": {"value": [2.18, 1.557, 1.669], "stderr": [None, 0.01, None]},
        "glass.absorption": {"value": [9.03, 4.21, 3.19], "stderr": [None, None, 0.5]},
        "environment.scale": {"value": [1.46], "stderr": [None]},
    }, holdout_rmse={"before": 0.27, "after": 0.143})
    checks = run_checks(summary, BOUNDS, KINDS)
    text = "\n".join(checks)
    assert "glass.ior = 2.18 is outside what a real dielectric has" in text
    assert "glass.ior: the photographs do not constrain component(s) [0, 2]" in text
    assert "environment.scale: the photographs do not constrain every component" in text
    assert "holdout RMSE after the fit (0.143) is 11.9 times the photographs' noise" in text


def test_bounds_and_trade_offs():
    summary = _summary(correlation={"names": ["glass.absorption[0]", "environment.scale"],
                                    "matrix": [[1.0, -0.995], [-0.995, 1.0]]})
    summary["parameters"]["glass.absorption"]["value"] = [0.0, 2.4, 1.1]
    checks = run_checks(summary, BOUNDS, KINDS)
    assert any("glass.absorption[0] = 0 sits at its lower bound 0" in c for c in checks)
    assert any("trade off (correlation -0.995)" in c for c in checks)


def test_trade_offs_are_judged_on_the_photographs_share():
    # The renders' Monte-Carlo error can correlate scalars that the photographs separate well:
    # the check reads the photographs' (Laplace) correlation when the fit gives it.
    together = {"names": ["glass.absorption[0]", "glass.absorption[1]"],
                "matrix": [[1.0, 0.995], [0.995, 1.0]]}
    apart = {"names": together["names"], "matrix": [[1.0, 0.4], [0.4, 1.0]]}
    summary = _summary(correlation=together, data_correlation=apart)
    assert not any("trade off" in c for c in run_checks(summary, BOUNDS, KINDS))
    summary = _summary(correlation=apart, data_correlation=together)
    assert any("trade off (correlation +0.995)" in c for c in run_checks(summary, BOUNDS, KINDS))


def test_without_holdout_views_the_training_residual_is_judged():
    summary = _summary(holdout_rmse={"before": None, "after": None},
                       train_rmse={"before": 0.3, "after": 0.2})
    assert any(c.startswith("The training RMSE") for c in run_checks(summary, BOUNDS, KINDS))


def test_a_value_the_photographs_barely_determine_is_said_not_measured():
    """The bowl of the glass suite: absorption 0.44 +- 1.7, 5.2 +- 4.2, 1.2 +- 1.7 per metre
    (truth 6, 2.5, 1); a clear glass at 0 +- 0.09 and a well-measured 6.1 +- 0.3 are not flagged."""
    steps = {"glass.absorption": [1.0, 1.0, 1.0], "glass.ior": [0.03], "environment.scale": [1.0]}
    summary = _summary()
    summary["parameters"]["glass.absorption"] = {"value": [0.44, 5.16, 1.19], "stderr": [1.7, 4.2, 1.7]}
    flagged = [c for c in run_checks(summary, BOUNDS, KINDS, steps) if "is not measured" in c]
    assert [c.split(" ")[0] for c in flagged] == [f"glass.absorption[{i}]" for i in range(3)]
    summary["parameters"]["glass.absorption"] = {"value": [0.0, 0.0, 6.1], "stderr": [0.09, 0.09, 0.3]}
    assert not any("is not measured" in c for c in run_checks(summary, BOUNDS, KINDS, steps))
    assert run_checks(_summary(), BOUNDS, KINDS, steps) == []


def test_a_parameter_the_renders_noise_moved_is_announced_once_the_spheres_are_not():
    """The glass suite's bowl: IOR 1.733 +- 0.014 for 1.52 with no check, its refinement's
    Gauss-Newton steps cut to the trust radius in 10 of 11 steps (the IOR's Jacobian columns from
    independent 64-spp renders: cosine -0.07 to 0.02, the curvature noise). The spheres' IORs had
    1-3 of 11 and their absorptions at most 6; clear glass walking at its bound 0 (sphere-1.47's
    absorption, 10 of 11) is the bound check's."""
    bowl = _summary()
    bowl["parameters"]["glass.ior"] = {"value": [1.7334] * 3, "stderr": [0.0141] * 3,
                                       "refinement_limited": [0.9167] * 3}
    bowl["parameters"]["glass.absorption"] = {"value": [7.589, 1.995, 0.449],
                                              "stderr": [2.59, 2.21, 1.96],
                                              "refinement_limited": [0.9167, 1.0, 1.0]}
    walks = [c for c in run_checks(bowl, BOUNDS, KINDS) if "random walk" in c]
    # The tied IOR once; the absorptions within two standard errors of 0 are left to the others.
    assert [c.split(" = ")[0] for c in walks] == ["glass.ior", "glass.absorption[0]"], walks
    assert "in 92% of the refinement's steps" in walks[0]
    # Its rerun walked to 1.071 +- 0.024 with 9 of 12 steps cut.
    bowl["parameters"]["glass.ior"] = {"value": [1.0707] * 3, "stderr": [0.024] * 3,
                                       "refinement_limited": [0.75] * 3}
    checks = run_checks(bowl, BOUNDS, KINDS)
    assert any(c.startswith("glass.ior = 1.071 +- 0.024: in 75%") for c in checks), checks

    sphere = _summary()
    sphere["parameters"]["glass.ior"]["refinement_limited"] = [0.25] * 3
    sphere["parameters"]["glass.absorption"]["refinement_limited"] = [0.36, 0.36, 0.55]
    assert run_checks(sphere, BOUNDS, KINDS) == []
    clear = _summary()
    clear["parameters"]["glass.absorption"] = {"value": [0.0009, 0.0086, 0.0086],
                                               "stderr": [0.11, 0.11, 0.1],
                                               "refinement_limited": [0.92, 0.92, 0.92]}
    assert not any("random walk" in c for c in run_checks(clear, BOUNDS, KINDS))


def test_standard_errors_without_their_monte_carlo_part_are_named():
    """Two refinement steps leave one averaged point: the renders' Monte-Carlo error of the values
    is not measured, and the standard errors (photographs' noise only) are said to be too small."""
    short = [c for c in run_checks(_summary(monte_carlo_points=1, method="lm"), BOUNDS, KINDS)
             if "Monte-Carlo error" in c]
    assert len(short) == 1 and "had 1" in short[0] and "--refinement-steps" in short[0]
    assert run_checks(_summary(monte_carlo_points=3, method="lm"), BOUNDS, KINDS) == []
    assert run_checks(_summary(monte_carlo_points=0, method="adam"), BOUNDS, KINDS) == []
