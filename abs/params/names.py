"""The catalogue of a scene's differentiable parameters.

Names follow the scene file: ``<material>.<field>``, ``environment.scale``,
``environment.rotation``, ``environment.orientation``, ``environment.inverse_distance``,
``environment.probe_fresnel``,
``sensor.<field>``, ``<object>.pose``, ``<object>.placement``.
Each has a size (3 for per-channel quantities), a unit and physical bounds; fitting code maps
bounds to unconstrained variables.

A material and an object may share a name (a ``cloth`` material on a ``cloth`` object):
``pose`` and ``placement`` are an object's only parameters (:data:`OBJECT_FIELDS`) and no material
may have a field of those names, so ``cloth.pose`` is the object's and every other
``cloth.<field>`` the material's.

Each :class:`Parameter` carries what its owner knows about it: its null value (where the effect it
models is absent, if it models one) and its setter (how it is written into a compiled scene), so
neither :class:`~abs.render.CompiledScene` nor the diagnosis effects branch on who owns it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abs.params.setters import AttributeSetter, PoseSetter, Setter

__all__ = ["Parameter", "parameter_specs", "POSE_FIELD", "PLACEMENT_FIELD", "OBJECT_FIELDS"]

INF = float("inf")

POSE_FIELD = "pose"
"""An object's rigid correction, ``<object>.pose``: ``[tx, ty, tz, rx, ry, rz]``."""

PLACEMENT_FIELD = "placement"
"""An object's correction on the ground plane, ``<object>.placement``: ``[tx, tz, ry]``, a slide
along x and z and a turn about +y (the pose ``[tx, 0, tz, 0, ry, 0]``): how an object standing on
a table is misplaced, with half the pose's freedoms (``docs/conventions.md``)."""

OBJECT_FIELDS = (POSE_FIELD, PLACEMENT_FIELD)
"""An object's parameters; reserved: no material may have a field so named."""


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
    typical_step : float or None
        The change over which images stay near linear in the parameter (its units), if the
        owner knows it better than the default of the fit's conditioning.
    reweighting : str or None
        How a path-length recording (:mod:`abs.render.path_lengths`) gives the image at another
        value of the parameter without rendering again: ``"absorption"`` (Beer-Lambert over the
        recorded lengths inside the owner material), ``"light_scale"`` (it multiplies all the
        light), ``"after_paths"`` (the sensor, applied to the path tracer's image); ``None``:
        a new value needs a new render.
    null : ndarray or None
        The value at which the parameter's effect is absent and the rendering is exactly the
        model without it (a roughness of 0, a pose of zeros, a linear response), ``size``
        entries; ``None`` for a parameter that is a quantity of the model rather than an
        extension of it (a reflectance, an IOR). See ``docs/scene-format.md``.
    setter : Setter or None
        Writes a (Dr.Jit) value into a :class:`~abs.render.CompiledScene`; ``setter(compiled,
        value)``. Supplied by the parameter's owner, so a new owner (a material type) brings its
        own and the compiled scene does not change.
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
    typical_step: float | None = None
    reweighting: str | None = None
    null: np.ndarray | None = field(default=None, compare=False)
    setter: Setter | None = field(default=None, compare=False, repr=False)

    @property
    def owner(self) -> str:
        return self.name.split(".", 1)[0]

    @property
    def field(self) -> str:
        return self.name.split(".", 1)[1]

    def at_null(self, value=None) -> bool:
        """Whether ``value`` (the scene file's, by default) is the null value; ``False`` for a
        parameter without one."""
        value = self.initial if value is None else value
        if self.null is None or value is None:
            return False
        return bool(np.array_equal(np.asarray(value, np.float64).ravel(), self.null))


def _null(value, size: int) -> np.ndarray | None:
    """``size`` entries from one number for all of them, or from ``size`` numbers."""
    return None if value is None else np.broadcast_to(np.asarray(value, np.float64), (size,)).copy()


#: Conditioning steps of sensor fields that the default (by unit and bound) would misjudge: a
#: colour matrix's diagonal sits at 1, its off-diagonal at 0, yet a change of 0.05 in any entry
#: is a 5 % change of a channel; a camera-matrix offset moves the image by about its size in
#: pixels, and images stay near linear over a fraction of a pixel, not over the bounds' 50; a
#: camera turn of 0.002 rad moves the image by a fraction of a pixel at the suite's focal lengths.
_SENSOR_STEPS = {"colour_matrix": 0.05, "intrinsics_offset": 0.3, "camera_turn": 0.002}


def parameter_specs(scene) -> dict[str, Parameter]:
    """All differentiable parameters of a :class:`~abs.scene.scene.Scene`, by name."""
    env = scene.environment
    specs = {
        "environment.scale": Parameter("environment.scale", 1, "1", 0.0, INF, np.array([env.scale]),
                                       reweighting="light_scale",
                                       setter=AttributeSetter("environment", "scale")),
        "environment.rotation": Parameter("environment.rotation", 1, "rad", -INF, INF,
                                          np.array([env.rotation]),
                                          setter=AttributeSetter("environment", "rotation")),
        # 1/R = 0 puts the map at infinity: no parallax, the plain model.
        "environment.inverse_distance": Parameter(
            "environment.inverse_distance", 1, "1/m", 0.0, INF, np.array([env.inverse_distance]),
            null=np.zeros(1), setter=AttributeSetter("environment", "inverse_distance")),
        # A rotation vector turning the map about all three axes; zeros: the orientation the
        # scene file gives. Lookups move, light paths do not (like ``rotation``).
        "environment.orientation": Parameter(
            "environment.orientation", 3, "rad, rad, rad", -INF, INF,
            np.asarray(env.orientation, np.float64), null=np.zeros(3),
            setter=AttributeSetter("environment", "orientation")),
        # The mirror ball's Fresnel left in a probe map, per channel (1: all of it); zeros: the
        # map as given. Channel c of the light, hence of the image, depends on c_c alone.
        "environment.probe_fresnel": Parameter(
            "environment.probe_fresnel", 3, "1", -0.9, 5.0, np.asarray(env.probe_fresnel, np.float64),
            separable_channels=True, null=np.zeros(3),
            setter=AttributeSetter("environment", "probe_fresnel")),
    }
    for field_name, (size, unit, lower, upper, null) in type(scene.sensor).FIELDS.items():
        # A response exponent and a stray-light level per channel act on their channel alone.
        specs[f"sensor.{field_name}"] = Parameter(
            f"sensor.{field_name}", size, unit, lower, upper,
            np.asarray(getattr(scene.sensor, field_name), np.float64),
            separable_channels=field_name in ("response", "stray_light"),
            typical_step=_SENSOR_STEPS.get(field_name), reweighting="after_paths",
            null=_null(null, size), setter=AttributeSetter("sensor", field_name))
    for name, material in scene.materials.items():
        for field_name, spec in material.parameters().items():
            initial = material.value(field_name) if spec.size != -1 and field_name in material._toml else None
            specs[f"{name}.{field_name}"] = Parameter(
                f"{name}.{field_name}", spec.size, spec.unit, spec.lower, spec.upper, initial,
                spec.moves_paths, spec.separable_channels and spec.size == 3,
                spec.difference_step, spec.typical_step, spec.reweighting,
                null=_null(spec.null, spec.size), setter=material.setter(field_name))
    for obj in scene.objects:
        specs[f"{obj.name}.{POSE_FIELD}"] = Parameter(
            f"{obj.name}.{POSE_FIELD}", 6, "m, m, m, rad, rad, rad", -INF, INF,
            np.asarray(obj.pose, dtype=np.float64), moves_paths=True, null=np.zeros(6),
            setter=PoseSetter(obj.name))
        specs[f"{obj.name}.{PLACEMENT_FIELD}"] = Parameter(
            f"{obj.name}.{PLACEMENT_FIELD}", 3, "m, m, rad", -INF, INF,
            np.asarray(obj.placement, dtype=np.float64), moves_paths=True, null=np.zeros(3),
            setter=PoseSetter(obj.name))
    return specs
