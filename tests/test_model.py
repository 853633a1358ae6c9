"""The forward model package: below fitting, sampling and diagnosis, built by one factory."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import abs as abs_package
from abs.errors import InputError

MODEL = Path(abs_package.__file__).parent / "model"


def test_the_model_imports_nothing_that_sits_above_it():
    above = ("abs.fitting", "abs.sampling", "abs.diagnosis")
    edges = []
    for path in sorted(MODEL.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):  # function-local imports included
            modules = ([a.name for a in node.names] if isinstance(node, ast.Import)
                       else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            edges += [f"{path.name} -> {m}" for m in modules if m.startswith(above)]
    assert not edges, edges


@pytest.fixture(scope="module")
def capture(small_scene_dir, tmp_path_factory):
    from abs import load_scene
    from abs.simulate import simulate_capture

    return simulate_capture(load_scene(small_scene_dir / "scene.toml"),
                            tmp_path_factory.mktemp("model") / "capture", n_cameras=3, width=16,
                            height=12, spp=8, n_holdout=1, seed=2)


def test_build_model_lays_out_the_parameters_and_shares_one_counter(small_scene_dir, capture):
    from abs.model import build_model

    model = build_model(small_scene_dir / "scene.toml", capture,
                        ["environment.scale", "glass.absorption"], {"environment.scale": [1.25]})
    assert model.names == ("environment.scale", "glass.absorption") and model.vector.size == 4
    assert model.vector.initial[0] == pytest.approx(1.25)
    train, holdout = model.problem("train", 2), model.problem("holdout")
    assert model.problem("train", 2) is train  # photographs are read once per resolution
    assert [o.holdout for o in train.observations] == [False, False]
    assert [o.holdout for o in holdout.observations] == [True]
    assert train.observations[0].photograph.shape == (6, 8, 3)
    assert len(model.problem("all").observations) == 3
    train.residuals(model.vector.initial, 1, seed=0)
    holdout.residuals(model.vector.initial, 1, seed=0)
    assert model.counter.renders == 3 and train.counter is holdout.counter is model.counter
    with pytest.raises(ValueError, match="views"):
        model.problem("test")


def test_build_model_refuses_what_cannot_be_fitted(small_scene_dir, capture):
    from abs.model import build_model

    with pytest.raises(InputError, match="unknown parameter"):
        build_model(small_scene_dir / "scene.toml", capture, ["glass.colour"])
    with pytest.raises(InputError, match="not among the fitted parameters"):
        build_model(small_scene_dir / "scene.toml", capture, ["environment.scale"],
                    {"glass.absorption": [1.0, 1.0, 1.0]})
    with pytest.raises(InputError, match="initial.glass.absorption"):
        build_model(small_scene_dir / "scene.toml", capture, ["glass.absorption"],
                    {"glass.absorption": np.ones(2)})
