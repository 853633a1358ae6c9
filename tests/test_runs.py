"""Run folders: resume identities keep their recipes (saved run folders must stay resumable)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import pytest

from abs.errors import InputError
from abs.runs.files import check_identity
from abs.runs.identity import digest, model_identity, run_identity


@dataclass
class _Settings:
    spp: int = 8
    downsample: int = 2
    clamp: float | None = None
    seed: int = 0
    max_iterations: int = 30
    schedule: tuple = ((0, 4), (10, 16))


class _Scene:
    def __init__(self, source):
        self.source = source


def test_fit_identity_is_the_recipe_abs_fit_saved(tmp_path):
    scene, capture, s = _Scene(tmp_path / "scene.toml"), tmp_path / "capture", _Settings()
    identity = run_identity(scene, capture, ["glass.ior"], s, initial={"glass.ior": [1.5]},
                            drop=("max_iterations",))
    # The dict abs fit wrote into checkpoint.json before run folders had one module.
    assert identity == {"scene": str(scene.source), "capture": str(capture.resolve()),
                        "parameters": ["glass.ior"], "initial": {"glass.ior": [1.5]},
                        "settings": {k: v for k, v in json.loads(json.dumps(asdict(s))).items()
                                     if k != "max_iterations"}}


def test_sample_identity_is_the_recipe_abs_sample_saved(tmp_path):
    s = _Settings()
    identity = run_identity(str(tmp_path / "scene.toml"), tmp_path / "capture", ["a"], s,
                            keep=("spp", "downsample", "clamp", "seed"))
    assert identity == {"scene": str(tmp_path / "scene.toml"), "capture": str((tmp_path / "capture").resolve()),
                        "parameters": ["a"], "settings": {"spp": 8, "downsample": 2, "clamp": None, "seed": 0}}


def test_model_identity_digests_the_file_and_digest_is_the_old_hash(tmp_path):
    path = tmp_path / "model.toml"
    path.write_text("[environment]\n")
    identity = model_identity(_Scene(path), tmp_path, ["a"], {"a": 1.0}, _Settings())
    assert identity["scene"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert identity["initial"] == {"a": 1.0} and identity["settings"]["schedule"] == [[0, 4], [10, 16]]
    task = {"seed": 1, "material": "alum-bronze"}
    assert digest(task) == hashlib.sha256(json.dumps(task, sort_keys=True).encode()).hexdigest()[:16]
    assert len(digest(task, 24)) == 24


def test_a_different_run_is_refused_naming_the_field():
    with pytest.raises(InputError, match=r"chain\.h5: abs\.parameters: chain was sampled with \['a'\]"):
        check_identity(Path("chain.h5"), "abs", {"parameters": ["a"]}, {"parameters": ["b"]},
                       "chain was sampled", "drop --resume")
    check_identity(Path("chain.h5"), "abs", {"parameters": ["a"], "extra": 1}, {"parameters": ["a"]}, "", "")


def test_a_capture_with_noise_images_is_another_run_than_the_same_folder_without(tmp_path):
    import numpy as np

    from abs.camera.pinhole import intrinsics_from_fov, look_at
    from abs.io.capture import load_capture, save_capture

    R, t = look_at([0, 0.1, 0.4], [0, 0, 0])
    views = [{"name": "v0", "K": intrinsics_from_fov(8, 6, np.deg2rad(40)), "R": R, "t": t}]
    image = np.full((6, 8, 3), 0.5, np.float32)
    save_capture(tmp_path / "capture", views, {"v0": image})
    scene, s = _Scene(tmp_path / "scene.toml"), _Settings()
    plain = run_identity(scene, tmp_path / "capture", ["a"], s)
    assert "pixel_weights" not in plain  # runs saved before noise images still resume
    # Rebuilt in place, now with the photographs' noise: its residuals are weighed.
    save_capture(tmp_path / "capture", views, {"v0": image}, noise={"v0": 0.01 + 0 * image})
    weighted = run_identity(scene, tmp_path / "capture", ["a"], s)
    assert weighted == {**plain, "pixel_weights": True}
    assert run_identity(scene, load_capture(tmp_path / "capture"), ["a"], s) == weighted
