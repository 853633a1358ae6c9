"""Synthetic glass captures shared by the sampling benchmarks (``sbc.py``,
``sampling_efficiency.py``): the default scene with a given absorption, one training and one
holdout view, sensor noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from abs.scene import load_scene
from abs.scene.write import write_scene
from abs.simulate import simulate_capture

ROOT = Path(__file__).resolve().parents[1]
PARAMETER = "glass.absorption"


def make_dataset(folder: Path, absorption: np.ndarray, width: int, height: int, seed: int,
                 photo_spp: int = 512) -> Path:
    """Write ``folder/scene.toml`` (the default scene with ``absorption``, 1/m per RGB) and a
    capture ``folder/capture`` of 2 views (the second held out); returns the capture folder.

    ``photo_spp``: the photographs' samples per pixel. Their Monte-Carlo noise is in no noise
    model (real photographs have none), and through glass it is heavy-tailed: keep it far below
    the sampler's."""
    scene = load_scene(ROOT / "scenes/default/scene.toml")
    folder.mkdir(parents=True, exist_ok=True)
    write_scene(scene, folder / "scene.toml", {PARAMETER: np.asarray(absorption, float)})
    simulate_capture(load_scene(folder / "scene.toml"), folder / "capture", n_cameras=2, n_holdout=1,
                     width=width, height=height, spp=photo_spp, shot_noise=1e-4, read_noise=0.003,
                     seed=seed)
    return folder / "capture"
