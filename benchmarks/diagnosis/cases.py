"""The diagnosis proof suite's scenes and cases: synthetic captures in which effects are present in
the photographs (the truth scene file) but absent from the scene file given to ``abs diagnose``.

Two scenes, built on the fly:

- ``sphere``: a glass sphere on a cloth in front of a printed checkerboard (the test scenes'
  layout) in a bright room (``tests/conftest.py``'s ``make_soft_env``); fitted: ``environment.scale``.
- ``box``: a painted box and a clear glass sphere on the cloth in front of the checkerboard;
  fitted: ``environment.scale`` and the paint's reflectance.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Case", "CASES", "QUICK", "build_scene"]


@dataclass(frozen=True)
class Case:
    """A capture with hidden effects: ``truth`` overrides TOML fields of the given scene."""

    name: str
    scene: str
    hidden: tuple[str, ...]            # effect names expected in the verdict, most important first
    truth: dict = field(default_factory=dict)   # parameter name -> true value


CASES = [
    Case("sphere-absorption", "sphere", ("absorption",), {"glass.absorption": [3.0, 6.0, 10.0]}),
    Case("sphere-vignetting", "sphere", ("vignetting",), {"sensor.vignetting": [-0.8, 0.0]}),
    Case("sphere-stray_light", "sphere", ("stray_light",), {"sensor.stray_light": [0.04, 0.04, 0.045]}),
    Case("sphere-null", "sphere", ()),
    Case("sphere-absorption+vignetting", "sphere", ("absorption", "vignetting"),
         {"glass.absorption": [3.0, 6.0, 10.0], "sensor.vignetting": [-0.8, 0.0]}),
    Case("box-pose", "box", ("pose",), {"box.pose": [0.004, 0.0, -0.003, 0.0, 0.04, 0.0]}),
    Case("box-pose-1cm", "box", ("pose",), {"box.pose": [0.01, 0.0, -0.008, 0.0, 0.1, 0.0]}),
    Case("box-camera_response", "box", ("camera_response",), {"sensor.response": [0.9, 0.9, 0.9]}),
    Case("box-null", "box", ()),
    Case("box-absorption+stray_light", "box", ("absorption", "stray_light"),
         {"glass.absorption": [3.0, 6.0, 10.0], "sensor.stray_light": [0.04, 0.04, 0.045]}),
    Case("box-vignetting", "box", ("vignetting",), {"sensor.vignetting": [-0.8, 0.0]}),
    Case("sphere-camera_response", "sphere", ("camera_response",), {"sensor.response": [0.9, 0.9, 0.9]}),
    Case("sphere-env_distance", "sphere", ("env_distance",), {"environment.inverse_distance": [2.0]}),
]

#: The quick default: one case per effect on either scene, a two-effect case and both nulls.
QUICK = ["sphere-absorption", "sphere-vignetting", "sphere-stray_light", "box-pose",
         "box-camera_response", "sphere-null", "box-null", "sphere-absorption+vignetting"]

_SPHERE = """
[render]
spp = 16
max_depth = 8

[environment]
file = "env.exr"
scale = 1.0

[materials.glass]
type = "dielectric"
ior = [1.5, 1.5, 1.5]
absorption = [0.0, 0.0, 0.0]

[materials.cloth]
type = "diffuse"
reflectance = [0.7, 0.7, 0.65]

[materials.backdrop]
type = "diffuse"
reflectance = "checker.png"

[[objects]]
name = "sphere"
mesh = "sphere.ply"
material = "glass"

[[objects]]
name = "floor"
mesh = "floor.ply"
material = "cloth"

[[objects]]
name = "board"
mesh = "backdrop.obj"
material = "backdrop"
"""

_BOX = """
[materials.paint]
type = "diffuse"
reflectance = [0.6, 0.4, 0.3]

[[objects]]
name = "box"
mesh = "box.ply"
material = "paint"
"""


def _assets(root: Path) -> None:
    import sys

    import trimesh

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
    from conftest import make_checker, make_soft_env, make_sphere_and_floor, write_mesh

    make_soft_env(root / "env.exr")
    make_checker(root / "checker.png")
    make_sphere_and_floor(root)
    back = trimesh.Trimesh(vertices=[[-0.3, 0, -0.12], [0.3, 0, -0.12], [0.3, 0.3, -0.12], [-0.3, 0.3, -0.12]],
                           faces=[[0, 1, 2], [0, 2, 3]], process=False)
    back.visual = trimesh.visual.TextureVisuals(uv=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
    write_mesh(root / "backdrop.obj", back)
    box = trimesh.creation.box(extents=[0.06, 0.05, 0.05])
    box.apply_translation([-0.07, 0.025, 0.0])
    write_mesh(root / "box.ply", box)


def build_scene(root: Path, kind: str) -> Path:
    """Write the assets and the given (effect-free) scene file of ``kind``; returns its path."""
    root.mkdir(parents=True, exist_ok=True)
    if not (root / "env.exr").exists():
        _assets(root)
    text = _SPHERE + (_BOX + '\n[fit]\nparameters = ["environment.scale", "paint.reflectance"]\n'
                      if kind == "box" else '\n[fit]\nparameters = ["environment.scale"]\n')
    path = root / f"{kind}.toml"
    path.write_text(text)
    return path
