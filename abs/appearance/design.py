"""The scene design of a characterisation: an open Cornell box with spheres of known materials.

After the tool-independent appearance paper (issue 29): a renderer is characterised on Cornell-box
scenes holding one sphere of a known material, for every material class, a few samples per class
and four wall colourings (red, green, blue, white). Held-out scenes hold several spheres of other
samples, in other positions, in front of walls of colours the characterisation never saw.

The box is open at the front (towards the camera) and at the top so that the environment map
lights it: abs's path tracer is lit by an environment only. Units: metres; colours: linear RGB.
Materials are abs's own material types (:mod:`abs.scene.materials`), given as scene-file fields.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

__all__ = ["MATERIAL_CLASSES", "WALL_COLOURS", "HELDOUT_WALL_COLOURS", "Sphere", "SceneSpec",
           "characterisation_design", "heldout_design", "design_digest"]

# Each class: samples as abs scene-file material tables. The first two samples characterise,
# the third is held out. ``merl`` samples name a material of the shared MERL neural fits.
MATERIAL_CLASSES: dict[str, tuple[dict, ...]] = {
    "car_paint": ({"type": "merl", "name": "blue-metallic-paint"},
                  {"type": "merl", "name": "green-metallic-paint"},
                  {"type": "merl", "name": "gold-metallic-paint"}),
    "plastic": ({"type": "plastic", "reflectance": [0.55, 0.06, 0.05], "roughness": 0.0},
                {"type": "plastic", "reflectance": [0.05, 0.12, 0.5], "roughness": 0.15},
                {"type": "plastic", "reflectance": [0.1, 0.45, 0.08], "roughness": 0.05}),
    "wood": ({"type": "diffuse", "reflectance": [0.32, 0.16, 0.07]},
             {"type": "diffuse", "reflectance": [0.55, 0.36, 0.18]},
             {"type": "diffuse", "reflectance": [0.2, 0.09, 0.04]}),
    "fabric": ({"type": "merl", "name": "blue-fabric"},
               {"type": "merl", "name": "pink-felt"},
               {"type": "merl", "name": "pink-fabric"}),
    "leather": ({"type": "plastic", "reflectance": [0.25, 0.11, 0.05], "roughness": 0.4},
                {"type": "plastic", "reflectance": [0.04, 0.04, 0.04], "roughness": 0.3},
                {"type": "plastic", "reflectance": [0.4, 0.3, 0.2], "roughness": 0.5}),
    "metal": ({"type": "conductor", "roughness": 0.1},
              {"type": "conductor", "eta": [0.2, 0.5, 1.5], "k": [3.6, 2.5, 1.9], "roughness": 0.25},
              {"type": "conductor", "eta": [1.2, 1.0, 0.8], "k": [7.0, 6.3, 5.3], "roughness": 0.15}),
    "glass": ({"type": "dielectric", "ior": 1.5},
              {"type": "roughdielectric", "ior": 1.5, "roughness": 0.1},
              {"type": "dielectric", "ior": 1.45}),
}
"""Material classes (after the paper's automotive ones, plus metal) and their samples."""

WALL_COLOURS: dict[str, tuple[float, float, float]] = {
    "red": (0.6, 0.08, 0.06), "green": (0.08, 0.5, 0.1), "blue": (0.07, 0.12, 0.6),
    "white": (0.72, 0.72, 0.7)}
"""The characterisation's wall colourings (back and side walls; the floor stays grey)."""

HELDOUT_WALL_COLOURS: dict[str, tuple[float, float, float]] = {
    "yellow": (0.6, 0.52, 0.08), "cyan": (0.08, 0.45, 0.55), "grey": (0.3, 0.3, 0.3),
    "magenta": (0.5, 0.1, 0.45)}
"""Wall colours of the held-out scenes, none of them seen by the characterisation."""

FLOOR = (0.5, 0.5, 0.5)


@dataclass(frozen=True)
class Sphere:
    """One sphere: centre and radius (metres), material class and sample index in that class.

    ``table`` (a scene-file material table), when given, replaces the class's sample.
    """

    centre: tuple[float, float, float]
    radius: float
    material_class: str
    sample: int
    table: dict | None = None

    @property
    def material(self) -> dict:
        return self.table if self.table is not None else MATERIAL_CLASSES[self.material_class][self.sample]


@dataclass(frozen=True)
class SceneSpec:
    """One scene of a design: a name, the wall colour (linear RGB) and its spheres.

    A sphere's material id in the geometry maps is its index in ``spheres`` plus one (0: no
    sphere); its class is ``spheres[id - 1].material_class``. ``box=False`` leaves the box out
    (the spheres alone under the environment: the closed-form case of the tests).
    """

    name: str
    walls: tuple[float, float, float]
    spheres: tuple[Sphere, ...]
    floor: tuple[float, float, float] = field(default=FLOOR)
    box: bool = True

    def to_json(self) -> dict:
        return {"name": self.name, "walls": list(self.walls), "floor": list(self.floor), "box": self.box,
                "spheres": [{"centre": list(s.centre), "radius": s.radius,
                             "class": s.material_class, "sample": s.sample, "material": s.material}
                            for s in self.spheres]}


def characterisation_design(samples: int = 2, classes: tuple[str, ...] | None = None,
                            walls: tuple[str, ...] | None = None) -> list[SceneSpec]:
    """The characterisation scenes: one sphere (radius 0.25 m, centre (0, 0.25, 0)) per scene.

    Parameters
    ----------
    samples : int
        Samples per class, 1 or 2 (the third is reserved for the held-out scenes). The paper used
        5 samples; abs scales the design down to run on two CPU cores.
    classes, walls : tuple of str, optional
        Subsets of :data:`MATERIAL_CLASSES` and :data:`WALL_COLOURS` (default: all).
    """
    if not 1 <= samples <= 2:
        raise ValueError(f"samples must be 1 or 2 (the third is held out), got {samples}")
    classes = tuple(MATERIAL_CLASSES) if classes is None else classes
    walls = tuple(WALL_COLOURS) if walls is None else walls
    return [SceneSpec(f"{cls}-{i}-{wall}", WALL_COLOURS[wall],
                      (Sphere((0.0, 0.25, 0.0), 0.25, cls, i),))
            for cls in classes for i in range(samples) for wall in walls]


def heldout_design() -> list[SceneSpec]:
    """Held-out scenes: three spheres each, new positions, new wall colours, held-out samples.

    Every class appears; glass appears in two scenes and is scored apart (its look is mostly the
    refracted box, which per-θ statistics describe poorly).
    """
    layout = (((-0.27, 0.16, 0.05), 0.16), ((0.05, 0.2, -0.15), 0.2), ((0.3, 0.13, 0.15), 0.13))
    groups = (("car_paint", "wood", "metal"), ("plastic", "fabric", "leather"),
              ("leather", "car_paint", "glass"), ("fabric", "metal", "plastic"))
    samples = ((2, 2, 2), (2, 2, 2), (2, 0, 2), (0, 1, 1))
    scenes = []
    for (wall, colour), classes, picks in zip(HELDOUT_WALL_COLOURS.items(), groups, samples):
        spheres = tuple(Sphere(centre, radius, cls, pick)
                        for (centre, radius), cls, pick in zip(layout, classes, picks))
        scenes.append(SceneSpec(f"heldout-{wall}", colour, spheres))
    return scenes


def design_digest(scenes: list[SceneSpec]) -> str:
    """A short hash of a design: two characterisations are comparable only on the same design."""
    text = json.dumps([s.to_json() for s in scenes], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def sphere_array(spec: SceneSpec) -> np.ndarray:
    """``(n, 4)`` array of the spheres' centres and radii (metres)."""
    return np.array([[*s.centre, s.radius] for s in spec.spheres], float)
