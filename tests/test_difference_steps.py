"""The central-difference step of an IOR chosen per fit from a pilot of its Jacobian column
(``abs.model.difference_steps``): the pilot's estimates, the rule, and a fit that uses it."""

from __future__ import annotations

import numpy as np
import pytest

from abs import load_scene
from abs.errors import InputError
from abs.fitting import FitSettings, fit
from abs.model import build_model
from abs.model.difference_steps import (MULTIPLES, _pick, choose_difference_steps,
                                        column_signal_and_noise)
from abs.simulate import simulate_capture


@pytest.fixture(scope="module")
def capture(small_scene_dir, tmp_path_factory):
    folder = tmp_path_factory.mktemp("steps") / "capture"
    simulate_capture(load_scene(small_scene_dir / "scene.toml"), folder, n_cameras=2, width=32,
                     height=24, spp=64, read_noise=0.003, seed=3)
    return folder


def test_signal_and_noise_of_independent_columns_are_unbiased():
    """Signal energy |E J|^2 without the noise's share, and the summed variance, over many draws
    of K = 8 columns with heavy-tailed noise (rare large jumps, as a difference through glass)."""
    rng = np.random.default_rng(0)
    mean = rng.normal(size=400)
    signals, noises = [], []
    for _ in range(400):
        jumps = rng.normal(size=(8, 400)) * (rng.random((8, 400)) < 0.05) * 8.0
        s, n = column_signal_and_noise(mean + rng.normal(size=(8, 400)) + jumps)
        signals.append(s)
        noises.append(n)
    true_noise = 400 * (1.0 + 0.05 * 64.0)
    assert np.mean(signals) == pytest.approx(mean @ mean, rel=3 * np.std(signals) / np.sqrt(400) / (mean @ mean) + 1e-3)
    assert np.mean(noises) == pytest.approx(true_noise, rel=0.02)
    # The self product would count the noise as signal: 400 * 4.2 / 8 on top.
    assert abs(np.mean(signals) - mean @ mean) < 0.2 * true_noise / 8


@pytest.mark.parametrize("tried, expected", [
    # The glass suite's sphere-1.52 (12 seeds at 120x100 over 2): the signal halves by 0.04.
    ([(0.02, 10914, 90105), (0.04, 5589, 36085), (0.08, 4318, 11741)], 0.02),
    # Its framed bowl: the signal stays while the noise falls.
    ([(0.02, 534, 78957), (0.04, 486, 29741), (0.08, 388, 12674)], 0.08),
    # No signal resolved at any step: the parameter's own.
    ([(0.02, -5.0, 100.0), (0.04, -1.0, 50.0), (0.08, -2.0, 20.0)], 0.02),
])
def test_the_step_with_least_noise_per_signal_that_keeps_the_signal(tried, expected):
    assert _pick([{"step": h, "signal": s, "noise": n} for h, s, n in tried]) == expected


def test_pilot_on_glass_before_a_checkerboard(small_scene_dir, capture):
    """The column's noise falls as the step grows (the jumps of edges seen through the glass are
    divided by 2h); the chosen step is one of those tried and is set in the compiled scene; the
    pilot's renders are counted."""
    model = build_model(small_scene_dir / "scene.toml", capture, ["glass.ior"], tied=["glass.ior"])
    problem = model.problem("train", 1)
    own = model.compiled.specs["glass.ior"].difference_step
    chosen = choose_difference_steps(problem, model.vector.initial, spp=8)["glass.ior"]
    assert [t["step"] for t in chosen.tried] == pytest.approx([own * m for m in MULTIPLES])
    noise = [t["noise"] for t in chosen.tried]
    assert noise[0] > noise[1] > noise[2], chosen.tried
    assert chosen.tried[0]["signal"] > 0.0, chosen.tried
    assert chosen.step == _pick(chosen.tried)
    assert model.compiled.specs["glass.ior"].difference_step == chosen.step
    assert model.counter.renders > 0


def test_auto_steps_are_chosen_once_recorded_and_used(small_scene_dir, capture):
    settings = FitSettings(spp=4, max_iterations=2, refinement_steps=0, tie=("glass.ior",),
                           difference_steps="auto")
    result = fit(small_scene_dir / "scene.toml", capture, ["glass.ior"], settings)
    summary = result.summary()["difference_steps"]["glass.ior"]
    assert summary["step"] in [t["step"] for t in summary["tried"]]
    assert len(summary["tried"]) == len(MULTIPLES)
    from abs.report.text import summary_lines

    assert any(line.startswith("difference step of glass.ior: ") for line in summary_lines(result.summary()))
    # Given steps render no pilot.
    given = FitSettings(spp=4, max_iterations=2, refinement_steps=0, tie=("glass.ior",),
                        difference_steps=(("glass.ior", summary["step"]),))
    plain = fit(small_scene_dir / "scene.toml", capture, ["glass.ior"], given)
    assert "difference_steps" not in plain.summary()
    assert plain.renders < result.renders


def test_bad_difference_steps_are_named(small_scene_dir, capture):
    with pytest.raises(ValueError, match="difference_steps"):
        FitSettings(difference_steps="sometimes")
    with pytest.raises(ValueError, match="step > 0"):
        FitSettings(difference_steps=(("glass.ior", -0.01),))
    with pytest.raises(InputError, match="not among the fitted"):
        build_model(small_scene_dir / "scene.toml", capture, ["glass.absorption"],
                    difference_steps={"glass.ior": 0.04})
    with pytest.raises(InputError, match="forward mode"):
        build_model(small_scene_dir / "scene.toml", capture, ["glass.absorption"],
                    difference_steps={"glass.absorption": 0.04})


def test_command_line_difference_steps():
    from abs.fitting.settings import parse_difference_steps

    assert parse_difference_steps(None) == ()
    assert parse_difference_steps("auto") == "auto"
    assert parse_difference_steps("glass.ior=0.04") == (("glass.ior", 0.04),)
    for bad in ("glass.ior", "glass.ior=-1", "=0.02", "glass.ior=x"):
        with pytest.raises(ValueError, match="--difference-steps"):
            parse_difference_steps(bad)


def test_short_fits_take_the_parameters_own_steps_or_the_given_ones():
    """The pilot runs at the full fit's start; the starts' short fits do not run their own."""
    from abs.fitting.starts import short_settings

    assert short_settings(FitSettings(difference_steps="auto")).difference_steps == ()
    given = (("glass.ior", 0.04),)
    assert short_settings(FitSettings(difference_steps=given)).difference_steps == given


def test_the_refinement_renders_at_its_own_samples_per_pixel(small_scene_dir, capture):
    """``refinement_spp`` changes the refinement's renders and nothing else: each refinement
    step renders three times the samples at 12 spp as at the fit's 4 (the IOR's column by
    central differences included)."""
    def samples(steps, **kw):
        settings = FitSettings(spp=4, max_iterations=2, refinement_steps=steps, tie=("glass.ior",),
                               difference_steps=(("glass.ior", 0.04),), **kw)
        return fit(small_scene_dir / "scene.toml", capture, ["glass.ior"], settings).summary()["samples_rendered"]

    own = samples(2) - samples(1)
    assert own > 0
    assert samples(2, refinement_spp=12) - samples(1, refinement_spp=12) == 3 * own
    with pytest.raises(ValueError, match="refinement_spp"):
        FitSettings(refinement_spp=0)
