"""The catalogue of model extensions that a diagnosis may find missing, and its registry.

An effect is one file in this folder defining a subclass of :class:`Effect` decorated with
:func:`register`. It knows where in a scene it can apply (:meth:`Effect.targets`: only where the
scene file leaves it out, i.e. at its null value and not fitted), how to add itself to a scene's
TOML data at its null value (:meth:`Effect.add`, so the extended scene renders exactly like the
given one), which parameters it releases to :func:`abs.fit` (:meth:`Effect.parameters`), and how
to say in physical terms what a fitted value means (:meth:`Effect.explain`).

Effects find where they apply by asking the scene's parameters and materials, never by naming
material types: a parameter's null value (:attr:`abs.params.Parameter.null`, see :func:`missing`)
and a material's capabilities (:attr:`abs.scene.materials.Material.transmissive`). So a new
material type with, say, an ``absorption`` field of null value 0 is a target of ``absorption``
without a change here, and a new effect is one new file.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["Effect", "Candidate", "register", "effect", "effects", "missing"]


@dataclass(frozen=True)
class Candidate:
    """One effect applied to one part of a scene.

    Attributes
    ----------
    effect : str
        Registry name (``absorption``, ``pose``, ``vignetting``...).
    target : str
        The material, object or table it applies to (``glass``, ``sphere``, ``sensor``).
    parameters : tuple of str
        Parameter names it releases to the fit (``glass.absorption``).
    """

    effect: str
    target: str
    parameters: tuple[str, ...]

    @property
    def label(self) -> str:
        return f"{self.effect}:{self.target}"


class Effect(ABC):
    """A physical effect that a scene file may leave out.

    Attributes
    ----------
    name : str
        Registry name, as it appears in ``diagnosis.json``.
    zero_null_derivative : bool
        The renderer's derivative at the null value vanishes (e.g. a roughness of 0), so a score
        test cannot see the effect; it is scored by a short fit instead.
    full_resolution : bool
        Its derivatives need renders at full resolution (pose: silhouette edge sampling).
    score_spp_factor : int
        The score test renders its residual and Jacobian at this many times the fits' samples
        per pixel (candidates scored together use the largest of theirs). The test's power grows
        with the samples: its noise is mostly the renders'.
    fit_spp_factor : int
        Fits of a model with the effect render at this many times the fits' samples per pixel
        (the largest of its effects'): for a parameter that reweights each sample by a different
        amount, so that a fixed-seed fit's noise depends on it and a fit at few samples follows
        the noise (the threads' lobes of ``cloth_anisotropy``).
    fit_refinement : bool
        ``False``: fits of a model with the effect skip the Gauss-Newton refinement after
        Levenberg-Marquardt (``refinement_steps = 0``): its steps come from the cross-curvature of
        two independent noisy Jacobians, which for such a parameter jumped by the whole trust
        radius in every coordinate; with ``fit_spp_factor`` the fixed seeds' bias it would
        average out is small.
    crossed_comparison : bool
        Models with and without the effect are compared on crossed errors of independent renders
        (:func:`abs.diagnosis.select.compare`), as those of effects that change the sampling are
        (``zero_null_derivative`` ones): its parameter reweights each sample by its own amount,
        so the two models' noise no longer cancels in a paired difference of shared seeds.
        BIC still compares the fits' training errors of shared seeds; the effect's extra
        per-sample variance can only raise its model's error there, so that test errs towards
        rejecting it.
    held_once_accepted : bool
        Once accepted, the effect's parameters are held at the accepted fit's values in every
        later fit and score of the diagnosis, and their needs (``full_resolution``,
        ``fit_spp_factor``, ``fit_refinement``) no longer set those fits' settings: for an effect
        whose fits are costly and that later refits at the diagnosis's samples did not improve
        (a pose: every later trial at full resolution, each with its own control).
    alternatives : tuple of str
        Effects that model the same error of the same target in another form (an object's
        ``placement`` and its ``pose``): once one is accepted for a target the others are no
        longer candidates there, and a clear winner never spares its alternatives' fits (only
        their fits tell the forms apart).
    """

    name: ClassVar[str]
    zero_null_derivative: ClassVar[bool] = False
    full_resolution: ClassVar[bool] = False
    score_spp_factor: ClassVar[int] = 4
    fit_spp_factor: ClassVar[int] = 1
    fit_refinement: ClassVar[bool] = True
    crossed_comparison: ClassVar[bool] = False
    held_once_accepted: ClassVar[bool] = False
    alternatives: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def targets(self, scene, compiled) -> list[str]:
        """Where the effect is missing in ``scene`` (a :class:`~abs.scene.scene.Scene`, with its
        :class:`~abs.render.CompiledScene`): names of materials, objects or tables at the null
        value whose parameters are not fitted."""

    @abstractmethod
    def add(self, data: dict, target: str) -> None:
        """Add the effect at its null value to a scene's TOML data (in place)."""

    @abstractmethod
    def parameters(self, target: str) -> tuple[str, ...]:
        """Parameter names the effect releases to the fit."""

    def probe(self, target: str) -> dict[str, list]:
        """Values a short fit starts from when :attr:`zero_null_derivative` is set (at the null
        value the fit would have no slope to follow); a small, plausible amount of the effect."""
        return {}

    @abstractmethod
    def explain(self, target: str, values: dict[str, np.ndarray]) -> str:
        """One or two sentences, in physical terms, on what the fitted ``values`` mean."""

    def candidates(self, scene, compiled) -> list[Candidate]:
        return [Candidate(self.name, t, self.parameters(t)) for t in self.targets(scene, compiled)]


def missing(scene, specs, name: str) -> bool:
    """Whether the scene leaves out the effect that parameter ``name`` models: the parameter
    exists, has a null value, the scene file sets it there, and ``[fit]`` does not release it.

    Parameters
    ----------
    scene : Scene
        The scene as given.
    specs : dict of str to Parameter
        Its parameters (:func:`abs.params.parameter_specs`, or ``CompiledScene.specs``).
    name : str
        A parameter name (``glass.absorption``, ``sensor.vignetting``).
    """
    spec = specs.get(name)
    return spec is not None and spec.at_null() and name not in scene.fit_parameters


_REGISTRY: dict[str, Effect] = {}


def register(cls: type[Effect]) -> type[Effect]:
    """Class decorator: make an effect available under ``cls.name``."""
    if cls.name in _REGISTRY and type(_REGISTRY[cls.name]) is not cls:
        raise ValueError(f"effect {cls.name!r} registered twice")
    _REGISTRY[cls.name] = cls()
    return cls


def effect(name: str) -> Effect:
    return _REGISTRY[name]


def effects() -> dict[str, Effect]:
    """Every registered effect, by name."""
    return dict(_REGISTRY)
