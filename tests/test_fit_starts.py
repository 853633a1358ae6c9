"""Several starts (``abs.fitting.starts``): which end is chosen, and the settings' checks."""

from __future__ import annotations

import numpy as np
import pytest

from abs import load_scene
from abs.fitting import FitSettings
from abs.fitting.settings import parse_starts
from abs.fitting.starts import _start_points, choose_start, short_settings
from abs.simulate import simulate_capture


@pytest.fixture(scope="module")
def capture(small_scene_dir, tmp_path_factory):
    folder = tmp_path_factory.mktemp("starts") / "capture"
    simulate_capture(load_scene(small_scene_dir / "scene.toml"), folder, n_cameras=3, width=40,
                     height=30, spp=128, read_noise=0.003, seed=5)
    return folder


class _Ended:
    """What choose_start reads of a short fit: where it ended and what it rendered."""

    def __init__(self, values):
        self.values, self.renders, self.samples_rendered = values, 0, 0


@pytest.mark.parametrize("order", [(1.0, 1.6), (1.6, 1.0)])
def test_the_end_nearest_the_truth_is_chosen_whatever_the_order(small_scene_dir, capture, order):
    """Two short fits that ended at the truth's scale (1.0) and off it (1.6): the scoring renders
    (fresh seed pairs, the two-seed objective) choose the truth's end, first or second."""
    ends = iter(order)

    def fake_fit(scene, capture, names, settings, initial):
        assert settings.max_iterations == 3 and settings.refinement_steps == 0 and not settings.starts
        return _Ended({"environment.scale": np.array([next(ends)])})

    settings = FitSettings(spp=8, max_iterations=3, starts=(("environment.scale", (0.5, 2.0)),))
    choice = choose_start(small_scene_dir / "scene.toml", capture, ["environment.scale"], settings,
                          run_fit=fake_fit)
    assert choice.values["environment.scale"] == pytest.approx([1.0])
    assert choice.tried[choice.chosen]["end"] == {"environment.scale": [1.0]}
    assert choice.tried[1 - choice.chosen]["objective"] > choice.tried[choice.chosen]["objective"]
    assert choice.renders > 0  # the scoring renders count


def test_starts_must_name_a_fitted_parameter(small_scene_dir, capture):
    settings = FitSettings(spp=4, starts=(("glass.ior", (1.5,)),))
    with pytest.raises(ValueError, match="glass.ior"):
        choose_start(small_scene_dir / "scene.toml", capture, ["environment.scale"], settings,
                     run_fit=lambda *a, **k: pytest.fail("no short fit may run"))


def test_start_points_and_short_settings():
    assert _start_points((("a.x", (1.0, 2.0)), ("b.y", (3.0,)))) == [{"a.x": 1.0, "b.y": 3.0},
                                                                     {"a.x": 2.0, "b.y": 3.0}]
    settings = FitSettings(downsample=2, downsample_schedule=((0, 4), (6, 2)), max_iterations=20,
                           refinement_steps=16, starts=(("glass.ior", (1.5,)),), polish_spp=1024)
    short = short_settings(settings)
    assert (short.downsample, short.downsample_schedule, short.refinement_steps, short.starts) == (4, (), 0, ())
    assert short.polish_spp is None  # short fits find a basin; only the full fit polishes


def test_parse_starts_and_settings_refuse_bad_values():
    assert parse_starts(["glass.ior=1.45,1.55", " environment.scale = 1"]) == (
        ("glass.ior", (1.45, 1.55)), ("environment.scale", (1.0,)))
    for bad in (["glass.ior"], ["glass.ior="], ["=1"], ["glass.ior=1,x"], ["glass.ior=inf"]):
        with pytest.raises(ValueError, match="--starts"):
            parse_starts(bad)
    for bad in ((("glass.ior", ()),), (("glass.ior",),), (("glass.ior", (float("nan"),)),)):
        with pytest.raises(ValueError, match="starts"):
            FitSettings(starts=bad)
