"""The one way to build the forward model that fitting, sampling and diagnosis share.

A fit, a posterior and a diagnosis all need the same objects: the scene compiled for the
renderer, the capture, the layout of the named parameters as one vector, and problems that
compare renderings with photographs over some views at some resolution. Built by hand in each
place they drifted apart in small ways (which values the layout starts from, which views, which
counter); :func:`build_model` builds them once, and :meth:`ForwardModel.problem` gives the
problems over it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from abs.errors import InputError
from abs.model.counter import RenderCounter
from abs.model.inputs import prepare
from abs.model.observations import boost_where_seen, observe
from abs.model.parameters import ParameterVector
from abs.model.problem import FitProblem

__all__ = ["ForwardModel", "build_model", "VIEWS"]

#: Which views of the capture a problem compares.
VIEWS = ("train", "holdout", "all")


@dataclass
class ForwardModel:
    """A compiled scene, its capture and the layout of the parameters that vary.

    Attributes
    ----------
    scene : Scene
        The scene as loaded (priors, render settings, materials).
    compiled : CompiledScene
        The scene compiled for the renderer; holds the current parameter values.
    capture : Capture
    vector : ParameterVector
        The varying parameters, laid out from their starting values.
    counter : RenderCounter
        Counts the renders of every problem of this model.
    reweight : bool
        Whether its problems render from path-length recordings where every varying parameter
        reweights (:attr:`~abs.model.problem.FitProblem.uses_recordings`).
    glass_spp_factor : int
        Pixels where glass is seen take this many times the samples per pixel
        (:func:`~abs.model.observations.boost_where_seen`; 1: none).
    """

    scene: object
    compiled: object
    capture: object
    vector: ParameterVector
    counter: RenderCounter = field(default_factory=RenderCounter)
    reweight: bool = True
    glass_spp_factor: int = 1
    _problems: dict = field(default_factory=dict, repr=False)

    @property
    def names(self) -> tuple[str, ...]:
        """The varying parameters' names, in the vector's order."""
        return self.vector.names

    def problem(self, views: str = "train", downsample: int = 1,
                clamp: float | None = None) -> FitProblem:
        """Residuals of this model against some of its capture's views.

        Problems are kept by their arguments: the photographs of a view are read and reduced
        once per resolution, however often a run asks (Adam's schedules switch back and forth).

        Parameters
        ----------
        views : {"train", "holdout", "all"}
            The capture's training views, holdout views, or all of them (in ``cameras.json``
            order).
        downsample : int
            Compare images box-averaged by this integer factor (renders at the reduced
            resolution).
        clamp : float or None
            Clamp renderings at this value before comparing (photographs that saturate).

        Returns
        -------
        FitProblem
            Shares this model's compiled scene, vector and counter.
        """
        if views not in VIEWS:
            raise ValueError(f"views must be one of {', '.join(VIEWS)}, not {views!r}")
        key = (views, int(downsample), clamp)
        if key not in self._problems:
            chosen = {"train": self.capture.train_views, "holdout": self.capture.holdout_views,
                      "all": self.capture.views}[views]
            glass = self.compiled.transmissive_bounds() if self.glass_spp_factor > 1 else []
            observed = [boost_where_seen(observe(v, downsample), glass, self.glass_spp_factor)
                        for v in chosen]
            self._problems[key] = FitProblem(self.compiled, self.vector, observed, clamp,
                                             counter=self.counter, reweight=self.reweight)
        return self._problems[key]


def build_model(scene, capture, parameters: Sequence[str] | None = None,
                initial: Mapping[str, object] | None = None, tied: Sequence[str] = (),
                reweight: bool = True, glass_spp_factor: int = 1,
                difference_steps: Mapping[str, float] | None = None) -> ForwardModel:
    """Load, compile and check a scene and capture, and lay out the parameters that vary.

    Parameters
    ----------
    scene : Scene or path
        The scene file (TOML) or a loaded scene; its current values are the starting point.
    capture : Capture or path
        The capture folder (``cameras.json``) or a loaded capture.
    parameters : sequence of str, optional
        Parameter names (``glass.absorption``, ``environment.scale``, ``sphere.pose``...);
        default: the scene's ``[fit] parameters``.
    initial : mapping, optional
        Starting values by parameter name (the parameters' units), instead of the scene's. They
        are written into the compiled scene, and the vector is laid out from the values it then
        holds.
    tied : sequence of str, optional
        Per-channel parameters to fit as one value for all channels (see
        :class:`~abs.model.parameters.ParameterVector`).
    reweight : bool
        Render from path-length recordings where the parameters allow (``False``: always render,
        as the seeds' scan does).
    glass_spp_factor : int
        More samples where glass is seen (:class:`ForwardModel`).
    difference_steps : mapping, optional
        Central-difference steps by parameter name (an IOR's; its units) instead of the
        parameters' own (:mod:`abs.model.difference_steps` chooses them).

    Returns
    -------
    ForwardModel

    Raises
    ------
    InputError
        No parameters, an unknown parameter name, no training view, or an ``initial`` value that
        names another parameter or has the wrong size.
    """
    scene, compiled, capture, names = prepare(scene, capture, parameters)
    for name, value in (initial or {}).items():
        if name not in names:
            raise InputError(None, "initial", f"{name!r} is not among the fitted parameters {names}")
        try:
            compiled.set(name, np.asarray(value, np.float64))
        except ValueError as exc:
            raise InputError(None, f"initial.{name}", str(exc)) from None
    try:
        vector = ParameterVector.build(compiled.specs, names, {n: compiled.get(n) for n in names},
                                       tuple(tied))
    except ValueError as exc:
        raise InputError(None, "tie", str(exc)) from None
    for name, step in (difference_steps or {}).items():
        if name not in names:
            raise InputError(None, "difference_steps", f"{name!r} is not among the fitted "
                                                       f"parameters {names}")
        try:
            compiled.set_difference_step(name, float(step))
        except ValueError as exc:
            raise InputError(None, f"difference_steps.{name}", str(exc)) from None
    if int(glass_spp_factor) < 1:
        raise InputError(None, "glass_spp_factor", f"must be >= 1, not {glass_spp_factor}")
    return ForwardModel(scene, compiled, capture, vector, reweight=reweight,
                        glass_spp_factor=int(glass_spp_factor))
