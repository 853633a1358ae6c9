"""``[fit.priors."NAME"]``: Gaussian priors in the scene file, validated at load time."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from abs.errors import SceneError
from abs.scene import Prior, load_scene


@pytest.fixture()
def scene_copy(small_scene_dir, tmp_path):
    for f in small_scene_dir.iterdir():
        shutil.copy(f, tmp_path / f.name)
    return tmp_path / "scene.toml"


def _with_priors(path, text):
    """Append prior tables after the scene's ``[fit]`` table (the last one in the file)."""
    path.write_text(path.read_text() + "\n" + text)
    return path


def test_no_priors_by_default(scene_copy):
    assert load_scene(scene_copy).fit_priors == {}


def test_priors_are_read_and_broadcast(scene_copy):
    _with_priors(scene_copy, """
[fit.priors."glass.ior"]
mean = [1.52, 1.53, 1.54]
sd = 0.01

[fit.priors."environment.scale"]
mean = 1
sd = [0.1]

[fit.priors."sphere.pose"]
mean = 0.0
sd = [0.001, 0.001, 0.001, 0.01, 0.01, 0.01]
""")
    priors = load_scene(scene_copy).fit_priors
    assert set(priors) == {"glass.ior", "environment.scale", "sphere.pose"}
    assert priors["glass.ior"].mean.tolist() == [1.52, 1.53, 1.54]
    assert priors["glass.ior"].sd.tolist() == [0.01] * 3
    assert priors["environment.scale"].mean.tolist() == [1.0]
    assert priors["environment.scale"].sd.tolist() == [0.1]
    assert priors["sphere.pose"].mean.tolist() == [0.0] * 6
    assert priors["sphere.pose"].sd.shape == (6,)
    with pytest.raises(ValueError):  # frozen all the way down
        priors["glass.ior"].mean[0] = 2.0


def test_prior_on_parameter_not_fitted_is_allowed(scene_copy):
    # Fitted parameters are chosen per run (e.g. on the command line); priors describe knowledge.
    _with_priors(scene_copy, '[fit.priors."cloth.reflectance"]\nmean = 0.7\nsd = 0.05\n')
    scene = load_scene(scene_copy)
    assert "cloth.reflectance" not in scene.fit_parameters
    assert scene.fit_priors["cloth.reflectance"].mean.tolist() == [0.7] * 3


@pytest.mark.parametrize("text,field,words", [
    ('[fit.priors."glass.iorr"]\nmean = 1.5\nsd = 0.1', 'fit.priors."glass.iorr"', "unknown parameter"),
    ('[fit.priors."glass.ior"]\nmean = [1.5, 1.5]\nsd = 0.1', 'fit.priors."glass.ior".mean', "shape [3]"),
    ('[fit.priors."glass.ior"]\nmean = 1.5\nsd = [0.1, 0.1, 0.1, 0.1]', 'fit.priors."glass.ior".sd', "shape [3]"),
    ('[fit.priors."glass.ior"]\nmean = 1.5\nsd = [0.1, 0.0, 0.1]', 'fit.priors."glass.ior".sd', "> 0"),
    ('[fit.priors."glass.ior"]\nmean = 1.5\nsd = -1', 'fit.priors."glass.ior".sd', "> 0"),
    ('[fit.priors."glass.ior"]\nmean = [1.5, nan, 1.5]\nsd = 0.1', 'fit.priors."glass.ior".mean', "NaN"),
    ('[fit.priors."glass.ior"]\nmean = 1.5\nsd = inf', 'fit.priors."glass.ior".sd', "infinity"),
    ('[fit.priors."glass.ior"]\nmean = "1.5"\nsd = 0.1', 'fit.priors."glass.ior".mean', "expected numbers"),
    ('[fit.priors."glass.ior"]\nmean = [true, 1, 1]\nsd = 0.1', 'fit.priors."glass.ior".mean', "expected numbers"),
    ('[fit.priors."glass.ior"]\nmean = 1.5', 'fit.priors."glass.ior".sd', "missing field"),
    ('[fit.priors."glass.ior"]\nmean = 1.5\nsd = 0.1\nsigma = 0.1', 'fit.priors."glass.ior".sigma', "unknown field"),
    ('[fit.priors]\n"glass.ior" = 1.5', 'fit.priors."glass.ior"', "expected a table"),
    ('[fit.priors."backdrop.reflectance"]\nmean = 0.5\nsd = 0.1', 'fit.priors."backdrop.reflectance"',
     "cannot have a prior"),
])
def test_bad_prior_is_named(scene_copy, text, field, words):
    _with_priors(scene_copy, text + "\n")
    with pytest.raises(SceneError) as info:
        load_scene(scene_copy)
    message = str(info.value)
    assert str(scene_copy) in message and f"{field}:" in message and words in message, message


def test_priors_not_a_table(scene_copy):
    scene_copy.write_text(scene_copy.read_text().replace(
        'parameters = ["glass.absorption"]', 'parameters = ["glass.absorption"]\npriors = 3'))
    with pytest.raises(SceneError, match=r"fit\.priors: expected a table"):
        load_scene(scene_copy)


def test_prior_checks_its_own_values():
    prior = Prior([1.0, 2.0], [0.5, 0.5])
    assert prior.mean.dtype == np.float64 and prior.sd.tolist() == [0.5, 0.5]
    with pytest.raises(ValueError, match="one size"):
        Prior([1.0, 2.0], [0.5])
    with pytest.raises(ValueError, match="sd > 0"):
        Prior([1.0], [0.0])
