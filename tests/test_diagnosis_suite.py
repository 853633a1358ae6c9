"""The diagnosis proof suite's cases are well formed: every hidden effect is in the catalogue, every
truth override lands in the truth scene, and every truth renderer accepts its settings.

The suite itself takes about half an hour (``benchmarks/diagnosis/run.py``); a case that names an
effect the catalogue lost, or a truth value no candidate carries, would otherwise only show there
(as a silently effect-free "photograph" and a wrong verdict).
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from conftest import assert_same_rendering, use_diagnosis_suite

use_diagnosis_suite()

from cases import CASES, QUICK, TRUTH_RENDERERS, build_scene  # noqa: E402
from run import FORMS, _truth_scene, summarise  # noqa: E402

from abs.diagnosis.effects import effects  # noqa: E402
from abs.params.names import parameter_specs  # noqa: E402
from abs.scene import load_scene  # noqa: E402


def test_case_names_are_unique_and_quick_is_a_subset():
    names = [c.name for c in CASES]
    assert len(names) == len(set(names))
    assert set(QUICK) <= set(names)
    # The quick suite names every effect of the catalogue at least once (an effect that is
    # another's form, run.FORMS, through the effect it is a form of), and has null cases.
    hidden = {e for c in CASES if c.name in QUICK for e in c.hidden}
    assert hidden == set(effects()) - set(FORMS) and set(FORMS.values()) <= hidden
    assert any(not c.hidden for c in CASES if c.name in QUICK)


def test_summary_keeps_gpu_wall_times_out_of_the_two_core_median():
    """The issue's time goal is for 2 cores: rows a GPU ran are summarised apart (and rows from
    before the device was recorded count as the CPU's), resumed rows not at all."""
    def row(name, hidden, verdict, wall, device=None):
        r = {"case": name, "hidden": hidden, "verdict": verdict, "first_correct": verdict[:1] == hidden[:1],
             "all_found": set(hidden) <= set(verdict), "wall_s": wall, "holdout_rmse_before": 0.05,
             "holdout_rmse_after": 0.04, "accepted_holdout": [[e, 0.05, 0.04] for e in verdict],
             "truth": {}, "recovered": {}}
        return r if device is None else {**r, "device": device}

    rows = [row("a", ["pose"], ["pose"], 500.0), row("b", [], [], 700.0, "llvm_ad_rgb on 2 CPU cores"),
            row("c", ["vignetting"], [], 90.0, "cuda_ad_rgb on NVIDIA H100 80GB HBM3"),
            {**row("d", ["pose"], ["pose"], 60.0), "resumed": True}]
    summary, markdown = summarise(rows, {"width": 160, "height": 120, "photo_spp": 256})
    # A resumed row (continued from checkpoints) took part of a diagnosis's time: not counted.
    assert summary["wall_s_per_diagnosis_median"] == 600.0
    assert summary["wall_s_per_diagnosis_median_gpu"] == 90.0
    assert summary["single_effect_first_verdict_accuracy"] == 2 / 3
    assert "| c (GPU) |" in markdown and "| a |" in markdown and "| d (resumed) |" in markdown


def test_a_pose_found_as_a_placement_is_compared_with_the_true_pose():
    """``placement`` names a hidden pose (``run.FORMS``); the table shows its value as that pose."""
    row = {"case": "box-pose", "hidden": ["pose"], "verdict": ["placement"], "first_correct": True,
           "all_found": True, "wall_s": 500.0, "holdout_rmse_before": 0.06, "holdout_rmse_after": 0.05,
           "accepted_holdout": [["placement", 0.06, 0.05]],
           "truth": {"box.pose": [0.004, 0, -0.003, 0, 0.04, 0]},
           "recovered": {"box.placement": [0.0036, -0.0027, 0.029]}}
    _, markdown = summarise([row], {"width": 160, "height": 120, "photo_spp": 256})
    assert ("box.pose: [0.0036, 0, -0.0027, 0, 0.029, 0] (as box.placement) "
            "vs [0.004, 0, -0.003, 0, 0.04, 0]") in markdown


@pytest.mark.parametrize("case", [c for c in CASES if c.photographs is not None], ids=lambda c: c.name)
def test_truth_renderers_accept_their_settings(case):
    kind, settings = case.photographs
    signature = inspect.signature(TRUTH_RENDERERS[kind])
    signature.bind(None, None, 1, 0, **settings)  # raises TypeError on a misspelt setting


def test_every_truth_override_lands_in_the_truth_scene(tmp_path):
    """The truth scene carries each override at its value; the given scene has none of them."""
    registry = effects()
    for case in CASES:
        assert set(case.hidden) <= set(registry), case.name
        if not case.truth:
            continue
        scene_path = build_scene(tmp_path / case.scene, case.scene)
        truth = parameter_specs(load_scene(_truth_scene(scene_path, case, tmp_path / case.name / "truth.toml")))
        given = parameter_specs(load_scene(scene_path))
        for name, value in case.truth.items():
            assert name in truth, (case.name, name)
            np.testing.assert_allclose(truth[name].initial, value, err_msg=f"{case.name}: {name}")
            before = given[name].initial if name in given else None
            assert before is None or not np.allclose(before, value), (case.name, name)


def test_turned_environment_photographs_are_what_orientation_models(tmp_path):
    """The truth renderer turns the map through its fixed frame (scipy's rotation), the fitted
    model through ``environment.orientation``: the same turn renders the same image (with a
    rotation about +y already in the scene, which the frame turn must commute past), and a
    visibly different one from the unturned map."""
    from abs.render import Camera, compile_scene
    from abs.simulate import place_cameras

    text = build_scene(tmp_path, "sphere").read_text().replace("scale = 1.0", "scale = 1.0\nrotation = 0.4", 1)
    (tmp_path / "turned.toml").write_text(text)
    compiled = compile_scene(load_scene(tmp_path / "turned.toml"))
    v = place_cameras(compiled, 1, 32, 24)[0]
    camera = Camera(np.asarray(v["K"]), np.asarray(v["R"]), np.asarray(v["t"]), 32, 24)
    turn = [0.14, 0.0, 0.09]
    truth = TRUTH_RENDERERS["turned_environment"](compiled, camera, 16, 3, rotation_vector=turn)
    plain = compiled.render(camera, spp=16, seed=3).numpy()
    compiled.set("environment.orientation", turn)
    model = compiled.render(camera, spp=16, seed=3).numpy()
    np.testing.assert_allclose(model, truth, atol=2e-5)  # measured 2.6e-6 at 64 spp
    assert np.abs(truth - plain).max() > 0.05


def test_clean_mesh_photographs_leave_the_noisy_scene_as_it_was(tmp_path):
    """The ``clean_glass_mesh`` truth renderer swaps the glass mesh's vertices and normals for the
    clean sphere's only while it renders: the photograph differs from the noisy scene's
    rendering, and the noisy scene renders as before afterwards."""
    from abs.render import Camera, compile_scene
    from abs.simulate import place_cameras

    compiled = compile_scene(load_scene(build_scene(tmp_path / "noisy", "noisy")))
    v = place_cameras(compiled, 1, 32, 24)[0]
    camera = Camera(np.asarray(v["K"]), np.asarray(v["R"]), np.asarray(v["t"]), 32, 24)
    before = compiled.render(camera, spp=16, seed=3).numpy()
    clean = TRUTH_RENDERERS["clean_glass_mesh"](compiled, camera, 16, 3, clean_mesh="sphere.ply")
    after = compiled.render(camera, spp=16, seed=3).numpy()
    assert_same_rendering(after, before)
    assert np.sqrt(np.mean((clean - before) ** 2)) > 0.003  # measured 0.010 at 48x36, 64 spp


def test_plain_mitsuba_photographs_agree_with_abs_to_noise(tmp_path):
    """The null case photographed by Mitsuba's own integrator and plugins is a null: its images
    differ from abs's rendering of the same scene by no more than two of abs's own renders with
    different seeds differ (the difference of independent renders is their Monte-Carlo noise)."""
    from abs.render import Camera, compile_scene
    from abs.simulate import place_cameras

    compiled = compile_scene(load_scene(build_scene(tmp_path, "sphere")))
    v = place_cameras(compiled, 1, 32, 24)[0]
    camera = Camera(np.asarray(v["K"]), np.asarray(v["R"]), np.asarray(v["t"]), 32, 24)
    mitsuba = TRUTH_RENDERERS["plain_mitsuba"](compiled, camera, 256, 1)
    ours, again = (compiled.render(camera, spp=256, seed=s).numpy() for s in (2, 3))
    rms = lambda a, b: float(np.sqrt(np.mean((a - b) ** 2)))  # noqa: E731
    assert rms(mitsuba, ours) < 1.3 * rms(again, ours), (rms(mitsuba, ours), rms(again, ours))
    assert abs(float(np.mean(mitsuba - ours))) < 0.2 * rms(again, ours)
