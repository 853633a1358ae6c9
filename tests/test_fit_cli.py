"""``abs fit`` and ``abs scan`` from the command line: outputs (public contract), resume, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from abs import load_scene
from abs.cli.main import main
from abs.simulate import simulate_capture


@pytest.fixture(scope="module")
def capture(small_scene_dir, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fit_cli") / "capture"
    scene = load_scene(small_scene_dir / "scene.toml")
    simulate_capture(scene, folder, n_cameras=3, width=40, height=30, spp=128, read_noise=0.003, seed=4)
    return folder


def _fit(small_scene_dir, capture, out, *extra):
    return main(["fit", str(small_scene_dir / "scene.toml"), str(capture), "--out", str(out),
                 "--params", "environment.scale", "--init", "environment.scale=1.4", "--spp", "8",
                 "--eval-spp", "8", *extra])


def test_fit_writes_the_contract_files(small_scene_dir, capture, tmp_path):
    out = tmp_path / "fit"
    assert _fit(small_scene_dir, capture, out, "--max-iterations", "6", "--refinement-steps", "2") == 0
    summary = json.loads((out / "fit.json").read_text())
    entry = summary["parameters"]["environment.scale"]
    assert set(entry) >= {"value", "stderr", "unit", "initial", "truth"}
    assert entry["initial"] == [pytest.approx(1.4)] and entry["truth"] == [pytest.approx(1.0)]
    assert abs(entry["value"][0] - 1.0) < 0.05 and entry["stderr"][0] > 0
    for key in ("train_rmse", "holdout_rmse", "train_ssim", "holdout_ssim"):
        assert summary[key]["after"] < summary[key]["before"] or key.endswith("ssim")
    assert summary["holdout_rmse"]["after"] < summary["holdout_rmse"]["before"]
    assert summary["renders"] > 0 and summary["samples_rendered"] > 0 and summary["wall_s"] > 0
    assert summary["iterations"] >= 3 and summary["method"] == "lm"
    assert summary["correlation"]["names"] == ["environment.scale"]
    assert summary["data_correlation"]["names"] == ["environment.scale"]
    fitted = load_scene(out / "scene.toml")  # loadable, assets re-rooted, value replaced
    assert fitted.environment.scale == pytest.approx(entry["value"][0])
    html = (out / "report" / "report.html").read_text()
    assert "environment.scale" in html and "holdout" in html
    assert sorted(p.name for p in (out / "renders").iterdir()) == ["v0.exr", "v1.exr", "v2.exr"]


def test_an_interrupted_fit_resumes_where_it_stopped(small_scene_dir, capture, tmp_path):
    out = tmp_path / "fit"
    assert _fit(small_scene_dir, capture, out, "--max-iterations", "2", "--refinement-steps", "0",
                "--no-report") == 0
    first = json.loads((out / "checkpoint.json").read_text())["state"]
    assert first["iteration"] == 2
    assert _fit(small_scene_dir, capture, out, "--max-iterations", "5", "--refinement-steps", "0",
                "--no-report", "--resume") == 0
    state = json.loads((out / "checkpoint.json").read_text())["state"]
    assert state["history"][:2] == first["history"]  # the first two iterations were kept, not redone
    assert state["iteration"] > 2
    # A checkpoint of a different fit is refused, naming what differs.
    assert main(["fit", str(small_scene_dir / "scene.toml"), str(capture), "--out", str(out),
                 "--params", "glass.absorption", "--resume"]) == 2


def test_fit_errors_name_the_problem(small_scene_dir, capture, tmp_path, capsys):
    assert main(["fit", str(small_scene_dir / "scene.toml"), str(capture), "--out", str(tmp_path),
                 "--params", "glass.colour"]) == 2
    assert "unknown parameter 'glass.colour'" in capsys.readouterr().err
    assert _fit(small_scene_dir, capture, tmp_path, "--init", "environment.scale=x") == 2
    assert "--init" in capsys.readouterr().err


def test_scan_finds_the_environment_scale(small_scene_dir, capture, tmp_path):
    out = tmp_path / "scan"
    assert main(["scan", str(small_scene_dir / "scene.toml"), str(capture), "--param",
                 "environment.scale", "--range", "0.7,1.3", "--points", "7", "--spp", "16",
                 "--downsample", "1", "--out", str(out)]) == 0
    summary = json.loads((out / "scan.json").read_text())
    assert abs(summary["minimum"][0] - 1.0) < 0.08
    assert len(summary["channels"][0]["rmse"]) == 7 and (out / "scan.png").stat().st_size > 0
    rmse = np.array(summary["channels"][0]["rmse"])
    assert rmse[0] > rmse.min() < rmse[-1]


def test_several_starts_choose_the_fit_start_and_survive_a_resume(small_scene_dir, capture, tmp_path,
                                                                   capsys):
    out = tmp_path / "fit"
    assert _fit(small_scene_dir, capture, out, "--starts", "environment.scale=0.5,1.6",
                "--max-iterations", "2", "--refinement-steps", "0") == 0
    summary = json.loads((out / "fit.json").read_text())
    assert "Several starts" in (out / "report" / "report.html").read_text()
    printed = capsys.readouterr().out
    assert "several starts: 2 short fits first (environment.scale = 0.5, 1.6)" in printed
    assert "start environment.scale 0.5 -> " in printed and "<- chosen" in printed
    starts = summary["starts"]
    assert [t["start"] for t in starts["tried"]] == [{"environment.scale": [0.5]},
                                                     {"environment.scale": [1.6]}]
    chosen = starts["tried"][starts["chosen"]]
    assert chosen["objective"] == min(t["objective"] for t in starts["tried"])
    # The full fit starts where the chosen short fit ended, and its renders are counted.
    assert summary["parameters"]["environment.scale"]["initial"] == pytest.approx(
        chosen["end"]["environment.scale"])
    assert summary["renders"] > starts["renders"] > 0
    saved = json.loads((out / "checkpoint.json").read_text())["state"]["start"]
    assert saved["tried"] == starts["tried"]
    # A resumed fit keeps its start and does not run the short fits again.
    assert _fit(small_scene_dir, capture, out, "--starts", "environment.scale=0.5,1.6",
                "--max-iterations", "4", "--refinement-steps", "0", "--no-report", "--resume") == 0
    resumed = json.loads((out / "fit.json").read_text())
    assert resumed["starts"] == starts
    assert resumed["parameters"]["environment.scale"]["initial"] == pytest.approx(
        chosen["end"]["environment.scale"])


def test_polish_is_reported_and_its_value_is_the_fits(small_scene_dir, capture, tmp_path, capsys):
    """``--polish-spp``: the IOR's last parabola is in fit.json (public contract), printed, and
    its value is the one reported and written to the fitted scene."""
    out = tmp_path / "fit"
    assert main(["fit", str(small_scene_dir / "scene.toml"), str(capture), "--out", str(out),
                 "--params", "glass.ior,environment.scale", "--tie", "glass.ior", "--init",
                 "glass.ior=1.52,1.52,1.52", "--spp", "8", "--eval-spp", "8", "--max-iterations", "2",
                 "--refinement-steps", "2", "--polish-spp", "16", "--polish-pairs", "2",
                 "--no-report"]) == 0
    summary = json.loads((out / "fit.json").read_text())
    (entry,) = summary["polish"]
    assert entry["name"] == "glass.ior" and entry["component"] == 0 and entry["spp"] == 16
    assert entry["offset"] == pytest.approx(0.2 * 0.02) and len(entry["vertices"]) == 2
    assert set(entry["slopes"]) == {"environment.scale"}
    assert summary["parameters"]["glass.ior"]["value"] == [pytest.approx(entry["value"])] * 3
    assert load_scene(out / "scene.toml").materials["glass"].ior_rgb[0] == pytest.approx(entry["value"])
    assert f"polish of glass.ior[0]: {entry['start']:.6g} -> {entry['value']:.6g}" in capsys.readouterr().out


@pytest.mark.parametrize("starts", ["environment.scale", "environment.scale=", "=1,2",
                                    "environment.scale=1,x", "environment.scale=nan"])
def test_bad_starts_are_named(small_scene_dir, capture, tmp_path, capsys, starts):
    assert _fit(small_scene_dir, capture, tmp_path, "--starts", starts) == 2
    assert "--starts" in capsys.readouterr().err
