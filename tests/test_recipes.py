"""The fitting recipes in ``fitting/``: environment_scale.py end to end, the others' --help."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

RECIPES = Path(__file__).resolve().parents[1] / "fitting"


def _run(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True,
                          timeout=600)


@pytest.mark.parametrize("script", ["glass_absorption_ior.py", "pose_refinement.py"])
def test_recipe_help(script):
    done = _run(RECIPES / script, "--help")
    assert done.returncode == 0, done.stderr
    assert "When to use it" in done.stdout


@pytest.mark.parametrize("starts", ["1.5,glass", "0.5,1.5", ""])
def test_glass_recipe_refuses_bad_starts(tmp_path, starts):
    done = _run(RECIPES / "glass_absorption_ior.py", tmp_path / "scene.toml", tmp_path,
                "--out", tmp_path / "fit", "--starts", starts)
    assert done.returncode == 2 and "--starts" in done.stderr, done.stderr


def test_environment_scale_recipe(small_scene_dir, tmp_path):
    from abs.scene import load_scene, write_scene
    from abs.simulate import simulate_capture

    truth = load_scene(small_scene_dir / "scene.toml")
    assert truth.environment.scale == 1.0
    capture = tmp_path / "capture"
    simulate_capture(truth, capture, n_cameras=3, width=48, height=36, spp=64)
    start = write_scene(truth, tmp_path / "start.toml", {"environment.scale": 1.4})

    out = tmp_path / "fit"
    done = _run(RECIPES / "environment_scale.py", start, capture, "--out", out)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "environment.scale = [" in done.stdout
    scale = json.loads((out / "fit.json").read_text())["parameters"]["environment.scale"]
    assert scale["value"][0] == pytest.approx(1.0, rel=0.05)
    assert scale["truth"] == [1.0]


def test_glass_recipe_takes_four_times_the_samples_on_a_gpu(monkeypatch):
    sys.path.insert(0, str(RECIPES))
    try:
        import glass_absorption_ior as recipe
    finally:
        sys.path.remove(str(RECIPES))
    cpu = recipe.settings()  # this machine: the LLVM (CPU) variant
    # The CPU finds the basin at 64 spp and refines at 256 (the glass suite's framed bowl).
    assert cpu.spp == 64 and cpu.refinement_spp == 256 and cpu.refinement_steps == 12
    assert cpu.polish_spp == 1024 and cpu.polish_pairs == 3
    monkeypatch.setattr(recipe, "current_backend", lambda: "cuda")
    cuda = recipe.settings()
    assert cuda.spp == 256 and cuda.glass_spp_factor == 4 and cuda.tie == ("glass.ior",)
    assert cuda.refinement_spp is None and cuda.refinement_steps == 16
