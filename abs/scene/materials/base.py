"""The material plugin interface and its registry.

A material type is one file in this folder defining a subclass of :class:`Material` decorated with
:func:`register`. The scene loader dispatches on the TOML ``type`` field through the registry, so
adding a material type never touches the loader.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from abs.params.setters import MaterialApplySetter, MitsubaKeySetter, Setter
from abs.scene.fields import Fields

__all__ = ["Material", "ParameterSpec", "register", "material_types", "material_class"]


@dataclass(frozen=True)
class ParameterSpec:
    """A differentiable field of a material.

    Parameters
    ----------
    field : str
        Name of the field in the scene file (``ior``, ``absorption``, ...).
    size : int
        Number of scalars (3 for per-channel quantities).
    unit : str
        Physical unit (``"1/m"``, ``"1"`` for dimensionless).
    lower, upper : float
        Physical bounds, inclusive.
    mitsuba_key : str or None
        Suffix of the Mitsuba parameter key below the material's id (``"ior"`` -> ``glass.ior``).
        ``None`` when the material computes the Mitsuba value itself (see :meth:`Material.apply`).
    moves_paths : bool
        Whether the field changes where light goes (a refractive index, a roughness), not only
        how much of it: its derivatives need attached paths (forward mode), and path replay
        cannot give them (see :meth:`abs.render.PathTracer.render_backward`).
    separable_channels : bool
        For a per-channel field (size 3): whether its channel ``c`` changes channel ``c`` of the
        image only (an absorption or IOR per colour channel, a reflectance colour). Then one
        forward-mode render along (1, 1, 1) gives all three Jacobian columns, channel by channel.
    difference_step : float or None
        When set, derivatives come from central differences of this step (in the field's unit)
        with common random numbers instead of forward mode: for fields that move the
        discontinuities seen *through* refraction (an IOR moves every edge and shadow seen through
        the glass). Forward mode leaves those edges' boundary terms out; the difference is the
        exact derivative of the image smoothed over +-step (a mollified derivative), boundaries
        at any depth included (see docs/renderer.md).
    typical_step : float or None
        The size of change over which the image stays close to linear in the field (its unit):
        a fit's first steps are about this large. ``None``: from the value and bounds
        (:func:`abs.model.parameters.typical_step`). An IOR needs it: the image of a
        checkerboard through a glass sphere is linear in the IOR over about 0.01 only, while the
        default (the distance from the bound, 0.5) let the first steps jump to IOR 2.
    reweighting : str or None
        ``"absorption"`` for a Beer-Lambert absorption inside the material, which a path-length
        recording reweights without rendering again (:mod:`abs.render.path_lengths`); ``None``
        otherwise.
    null : float or None
        The value (every entry) at which the effect the field models is absent, so that the
        material renders exactly as without it (an absorption or roughness of 0); ``None`` for a
        field that is a quantity of the model (an IOR, a reflectance). Diagnosis effects find
        where they are missing by it (:attr:`abs.params.Parameter.null`).
    """

    field: str
    size: int
    unit: str
    lower: float
    upper: float
    mitsuba_key: str | None
    moves_paths: bool = False
    separable_channels: bool = False
    difference_step: float | None = None
    typical_step: float | None = None
    reweighting: str | None = None
    null: float | None = None


class Material(ABC):
    """A named material of a scene.

    Subclasses are immutable descriptions parsed from the scene file; :meth:`to_mitsuba` turns
    them into a Mitsuba BSDF dictionary.

    Attributes
    ----------
    type_name : str
        The scene file's ``type``.
    transmissive : bool
        Light passes through the material (glass): code that must treat glass apart asks this
        rather than naming types (the pose effect leaves glass objects out, absorption and
        surface roughness apply to glass only).
    """

    type_name: ClassVar[str]
    transmissive: ClassVar[bool] = False

    def __init__(self, name: str):
        self.name = name

    @classmethod
    @abstractmethod
    def from_fields(cls, name: str, fields: Fields) -> "Material":
        """Parse the material's TOML table (``fields.table`` includes ``type``)."""

    @abstractmethod
    def to_mitsuba(self) -> dict:
        """The Mitsuba BSDF dictionary for this material."""

    def to_toml(self) -> dict:
        """The TOML table that reproduces this material (for writing fitted scenes)."""
        return dict(self._toml)

    def file_fields(self) -> dict[str, Path]:
        """Fields of :meth:`to_toml` that name asset files, with the absolute files they name.

        Filled by the loader from what :meth:`Fields.file` resolved, so a material type gets its
        paths rewritten by :func:`abs.scene.write.write_scene` without declaring them.
        """
        return dict(self._files)

    def parameters(self) -> dict[str, ParameterSpec]:
        """Differentiable fields, keyed by field name."""
        return {}

    def value(self, field: str) -> np.ndarray:
        """Current value of a differentiable field as given in the scene file."""
        return np.atleast_1d(np.asarray(self._toml[field], dtype=np.float64))

    def setter(self, field: str) -> Setter:
        """How the compiled scene writes the differentiable ``field``
        (:attr:`abs.params.Parameter.setter`): into the Mitsuba parameter ``<name>.<mitsuba_key>``
        as it is, or, for a field without a ``mitsuba_key``, through :meth:`apply`. A material
        type that needs another binding overrides this.
        """
        key = self.parameters()[field].mitsuba_key
        if key is None:
            return MaterialApplySetter(self.name, field)
        return MitsubaKeySetter(f"{self.name}.{key}")

    def apply(self, field: str, value, mitsuba_params) -> None:
        """Write a field whose ``mitsuba_key`` is ``None`` into the Mitsuba parameters.

        ``value`` is a Dr.Jit array (possibly attached to the AD graph).
        """
        raise NotImplementedError(f"{type(self).__name__}.{field} has no custom binding")

    _toml: dict
    _files: dict[str, Path] = {}  # set by the loader; shared default is never mutated


_REGISTRY: dict[str, type[Material]] = {}


def register(cls: type[Material]) -> type[Material]:
    """Class decorator: make a material type available under ``cls.type_name``."""
    if cls.type_name in _REGISTRY and _REGISTRY[cls.type_name] is not cls:
        raise ValueError(f"material type {cls.type_name!r} registered twice")
    _REGISTRY[cls.type_name] = cls
    return cls


def material_types() -> list[str]:
    return sorted(_REGISTRY)


def material_class(type_name: str) -> type[Material] | None:
    return _REGISTRY.get(type_name)

