"""The forward model: a scene and a capture turned into residuals and their derivatives.

Fitting finds the parameter values that make renderings match photographs, sampling explores
which values are plausible, and diagnosis asks which effects the scene lacks; all three compare
the same renderings with the same photographs. This package is that comparison, below all three
(it imports none of them): :func:`build_model` loads and compiles a scene and capture and lays out
the named parameters as one vector (:class:`ParameterVector`), and
:meth:`ForwardModel.problem` gives a :class:`FitProblem` whose residuals and Jacobians come from
the differentiable renderer.
"""

from abs.model.build import ForwardModel, build_model
from abs.model.counter import RenderCounter
from abs.model.noise import estimate_image_noise
from abs.model.observations import Observation, observe
from abs.model.parameters import ParameterVector, typical_step
from abs.model.problem import FitProblem, render_views

__all__ = ["build_model", "ForwardModel", "FitProblem", "ParameterVector", "typical_step",
           "Observation", "observe", "RenderCounter", "render_views", "estimate_image_noise"]
