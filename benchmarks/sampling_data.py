"""Synthetic glass captures shared by the sampling benchmarks (``sbc.py``,
``sampling_efficiency.py``): a scene with a given absorption, one training and one holdout view,
sensor noise. Scenes: ``default`` (the embedded default scene: glass on a cloth before a
checkerboard) and ``sphere`` (the test suite's glass sphere alone under an enclosure with one
bright band: fast, and its Monte-Carlo noise through the glass is strongly heavy-tailed)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from abs.scene import load_scene
from abs.scene.write import write_scene
from abs.simulate import simulate_capture

ROOT = Path(__file__).resolve().parents[1]
PARAMETER = "glass.absorption"


def make_dataset(folder: Path, absorption: np.ndarray, width: int, height: int, seed: int,
                 photo_spp: int = 512, scene: str = "default") -> Path:
    """Write ``folder/scene.toml`` (scene ``scene`` with ``absorption``, 1/m per RGB) and a
    capture ``folder/capture`` of 2 views (the second held out); returns the capture folder.

    ``photo_spp``: the photographs' samples per pixel. Their Monte-Carlo noise is in no noise
    model (real photographs have none), and through glass it is heavy-tailed: keep it far below
    the sampler's."""
    folder.mkdir(parents=True, exist_ok=True)
    source = ROOT / "scenes/default/scene.toml" if scene == "default" else _sphere_scene(folder)
    write_scene(load_scene(source), folder / "scene.toml", {PARAMETER: np.asarray(absorption, float)})
    simulate_capture(load_scene(folder / "scene.toml"), folder / "capture", n_cameras=2, n_holdout=1,
                     width=width, height=height, spp=photo_spp, shot_noise=1e-4, read_noise=0.003,
                     seed=seed)
    return folder / "capture"


def _sphere_scene(folder: Path) -> Path:
    """The test suite's glass sphere (``tests/conftest.py``) alone under its enclosure map."""
    tests = str(ROOT / "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)
    from conftest import make_env, make_sphere_and_floor

    make_sphere_and_floor(folder)
    make_env(folder / "env.exr")
    path = folder / "sphere.toml"
    path.write_text('[environment]\nfile = "env.exr"\n\n[materials.glass]\ntype = "dielectric"\n'
                    'ior = [1.5, 1.5, 1.5]\nabsorption = [2.0, 4.0, 8.0]\n\n[[objects]]\n'
                    'name = "sphere"\nmesh = "sphere.ply"\nmaterial = "glass"\n')
    return path
