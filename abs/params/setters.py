"""How a parameter's value is written into a compiled scene: one small class per kind of owner.

A :class:`~abs.params.names.Parameter` carries one of these (its owner chooses which), and
:meth:`abs.render.CompiledScene.set` calls it, so the compiled scene holds no list of owners.
They are duck-typed against the compiled scene (its ``environment``, ``sensor``, ``params``,
``scene``, :meth:`~abs.render.CompiledScene.write_mitsuba`,
:meth:`~abs.render.CompiledScene.move_object` and
:meth:`~abs.render.CompiledScene.set_normal_smoothing`), so this module imports nothing from the renderer and
the parameter catalogue stays below it in the layers. Plain classes rather than closures: they
compare, print and pickle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

__all__ = ["Setter", "AttributeSetter", "PoseSetter", "NormalSmoothingSetter", "MitsubaKeySetter",
           "MaterialApplySetter"]


class Setter(Protocol):
    """``setter(compiled, value)``: write ``value`` (a Dr.Jit ``Float``, possibly attached to
    the AD graph) into ``compiled``, a :class:`~abs.render.CompiledScene`."""

    def __call__(self, compiled, value) -> None: ...


@dataclass(frozen=True)
class AttributeSetter:
    """An attribute of one of the compiled scene's members (``environment.scale``: the
    :class:`~abs.render.environment.Environment`'s ``scale``; ``sensor.response``)."""

    member: str
    attribute: str

    def __call__(self, compiled, value) -> None:
        setattr(getattr(compiled, self.member), self.attribute, value)


@dataclass(frozen=True)
class PoseSetter:
    """An object's pose or placement: its mesh is moved rigidly (see ``docs/conventions.md``).
    The compiled scene composes the two from the values it has recorded, so both parameters
    share this setter."""

    obj: str

    def __call__(self, compiled, value) -> None:
        compiled.move_object(self.obj)


@dataclass(frozen=True)
class NormalSmoothingSetter:
    """The shading normals of every mesh of a material, smoothed towards (or pushed away from)
    their neighbours' (:meth:`abs.render.CompiledScene.set_normal_smoothing`)."""

    material: str

    def __call__(self, compiled, value) -> None:
        compiled.set_normal_smoothing(self.material, value)


@dataclass(frozen=True)
class MitsubaKeySetter:
    """A Mitsuba scene parameter that holds the value as it is (``glass.ior``,
    ``cloth.reflectance.value``)."""

    key: str

    def __call__(self, compiled, value) -> None:
        compiled.write_mitsuba(self.key, value)


@dataclass(frozen=True)
class MaterialApplySetter:
    """A material field the material itself turns into Mitsuba values
    (:meth:`abs.render.CompiledScene.bind_material`: a PCA table from its coefficients)."""

    material: str
    field: str

    def __call__(self, compiled, value) -> None:
        compiled.bind_material(self.material, self.field, value)
