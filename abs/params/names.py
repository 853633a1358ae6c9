"""The catalogue of a scene's differentiable parameters.

Names follow the scene file: ``<material>.<field>``, ``environment.scale``,
``environment.rotation``, ``environment.inverse_distance``, ``sensor.<field>``, ``<object>.pose``. Each has a size (3 for per-channel quantities), a
unit and physical bounds; fitting code (later) maps bounds to unconstrained variables.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Parameter", "parameter_specs"]

INF = float("inf")


@dataclass(frozen=True)
class Parameter:
    """A differentiable scene parameter.

    Attributes
    ----------
    name : str
        ``<owner>.<field>``.
    size : int
        Number of scalars (-1: known only once the scene is compiled, e.g. a texture).
    unit : str
        Physical unit of each scalar.
    lower, upper : float
        Inclusive physical bounds.
    initial : ndarray or None
        Value in the scene file.
    moves_paths : bool
        Whether the parameter moves light paths (geometry, refraction) rather than only scaling
        what they carry: its derivatives come from forward mode, never from path replay.
    separable_channels : bool
        Per-channel parameter whose channel ``c`` changes image channel ``c`` only (one forward
        render gives its three Jacobian columns).
    difference_step : float or None
        Derivatives by common-random-number central differences of this step (parameter units)
        rather than forward mode (see :class:`abs.scene.materials.base.ParameterSpec`).
    """

    name: str
    size: int
    unit: str
    lower: float
    upper: float
    initial: np.ndarray | None
    moves_paths: bool = False
    separable_channels: bool = False
    difference_step: float | None = None

    @property
    def owner(self) -> str:
        return self.name.split(".", 1)[0]

    @property
    def field(self) -> str:
        return self.name.split(".", 1)[1]


def parameter_specs(scene) -> dict[str, Parameter]:
    """All differentiable parameters of a :class:`~abs.scene.scene.Scene`, by name."""
    env = scene.environment
    specs = {
        "environment.scale": Parameter("environment.scale", 1, "1", 0.0, INF, np.array([env.scale])),
        "environment.rotation": Parameter("environment.rotation", 1, "rad", -INF, INF,
                                          np.array([env.rotation])),
        "environment.inverse_distance": Parameter("environment.inverse_distance", 1, "1/m", 0.0, INF,
                                                  np.array([env.inverse_distance])),
    }
    for field, (size, unit, lower, upper, _) in type(scene.sensor).FIELDS.items():
        # A response exponent and a stray-light level per channel act on their channel alone.
        specs[f"sensor.{field}"] = Parameter(f"sensor.{field}", size, unit, lower, upper,
                                             np.asarray(getattr(scene.sensor, field), np.float64),
                                             separable_channels=field in ("response", "stray_light"))
    for name, material in scene.materials.items():
        for field, spec in material.parameters().items():
            initial = material.value(field) if spec.size != -1 and field in material._toml else None
            specs[f"{name}.{field}"] = Parameter(f"{name}.{field}", spec.size, spec.unit,
                                                 spec.lower, spec.upper, initial, spec.moves_paths,
                                                 spec.separable_channels and spec.size == 3,
                                                 spec.difference_step)
    for obj in scene.objects:
        specs[f"{obj.name}.pose"] = Parameter(f"{obj.name}.pose", 6, "m, m, m, rad, rad, rad",
                                              -INF, INF, np.asarray(obj.pose, dtype=np.float64),
                                              moves_paths=True)
    return specs
