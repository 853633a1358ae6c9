"""Scene files extended by candidate effects: the given scene plus effects, at given values.

A diagnosis compares models that differ only by effects added on top of the user's scene file. Each
model is written as a real scene file (so a finding can be opened, rendered and refitted by hand)
and read back with :func:`~abs.scene.load_scene`, which validates it like any user file.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import tomli_w

from abs.diagnosis.effects import Candidate, effect
from abs.model import build_model
from abs.scene.load import load_scene
from abs.scene.scene import Scene
from abs.scene.write import scene_table, write_scene

__all__ = ["extend_scene", "render_problem"]


def extend_scene(scene: Scene, candidates: Sequence[Candidate], values: Mapping[str, object],
                 path: str | Path) -> Scene:
    """Write ``scene`` with ``candidates`` added and ``values`` set, and load it back.

    Parameters
    ----------
    scene : Scene
        The scene as the user gave it.
    candidates : sequence of Candidate
        Effects to add, each at its null value unless ``values`` names its parameters.
    values : mapping
        Parameter values by name (fitted baseline parameters, fitted effect parameters).
    path : str or Path
        The scene file to write (its ``[fit] parameters`` lists the scene's and the effects').

    Returns
    -------
    Scene
    """
    path = Path(path).resolve()
    data = scene_table(scene, path.parent, {})
    names = list(scene.fit_parameters)
    for c in candidates:  # at the null value first: ``values`` are written over it below
        effect(c.effect).add(data, c.target)
        names += [p for p in c.parameters if p not in names]
    if names:
        data.setdefault("fit", {})["parameters"] = names
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"# Written by abs diagnose: {scene.source} with "
                    f"{', '.join(c.label for c in candidates) or 'no effect added'}.\n\n"
                    + tomli_w.dumps(data), encoding="utf-8")
    extended = load_scene(path)
    if values:
        write_scene(extended, path, values)
        extended = load_scene(path)
    return extended


def render_problem(scene: Scene, capture, names: Sequence[str], holdout: bool, factor: int,
                   clamp: float | None, values: Mapping[str, object] | None = None):
    """``(compiled, vector, theta, problem)``: ``scene`` compiled with ``names`` as its parameters,
    their values ``theta`` (``values``, or exactly the scene's own: null values stay unclipped) and
    a :class:`~abs.model.problem.FitProblem` over the training (or holdout) views downsampled by
    ``factor``, with the fits' ``clamp``."""
    model = build_model(scene, capture, tuple(names),
                        None if values is None else {n: values[n] for n in names})
    compiled, names = model.compiled, model.names
    current = {n: np.asarray(values[n] if values is not None else compiled.get(n), float).ravel()
               for n in names}
    problem = model.problem("holdout" if holdout else "train", factor, clamp)
    return compiled, model.vector, np.concatenate([current[n] for n in names]), problem
