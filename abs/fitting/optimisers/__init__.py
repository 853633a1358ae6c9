"""Optimisers of a fit, registered by name: one file each, ``<name>.py``.

A fit is an objective (:class:`~abs.fitting.objective.Objective`: weighted residuals, their
Jacobian and the gradient over the unconstrained vector ``z``) plus an optimiser looked up here by
the name in :attr:`FitSettings.method <abs.fitting.settings.FitSettings.method>`. As optimistix
and optax keep theirs, each optimiser is an object, and what it must remember between iterations is a
typed state of its own (a frozen dataclass), not a shared dictionary: a resumed fit restores
exactly those fields, and a mistyped one fails at once.

Adding an optimiser is adding a file ``abs/fitting/optimisers/<name>.py`` that defines an
:class:`Optimiser` subclass decorated with ``@register("<name>")``: the file name is the name, so
that :func:`names` (settings validation, the CLI's ``--method`` choices) lists the optimisers
without importing them (which would import JAX and the renderer).

What every optimiser shares, the run's iteration count, its point ``z`` and its history, is
:class:`OptimizerState`, the content of a fit's ``checkpoint.json``.
"""

from __future__ import annotations

import abc
import importlib
import pkgutil
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar

import numpy as np

__all__ = ["Optimiser", "OptimizerState", "Callback", "register", "get", "names"]

_REGISTRY: dict[str, type["Optimiser"]] = {}


@dataclass
class OptimizerState:
    """Where an optimisation stands (JSON-serialisable through :meth:`to_dict`).

    Attributes
    ----------
    method : str
        The optimiser's registered name (``"lm"``, ``"adam"``).
    iteration : int
        Iterations done.
    z : ndarray
        Current unconstrained parameters (typical steps; LM: the last accepted point).
    history : list of dict
        One entry per iteration: ``iteration``, ``loss`` (RMSE of the residuals, linear RGB),
        ``z``.
    solver : object or None
        The optimiser's own typed state (its :attr:`Optimiser.State`); ``None`` before its first
        iteration.
    start : dict or None
        Where several starts sent the fit (:meth:`abs.fitting.starts.StartChoice.to_dict`), so
        that a resumed fit neither runs them again nor forgets where it started.
    """

    method: str
    iteration: int
    z: np.ndarray
    history: list[dict] = field(default_factory=list)
    solver: Any = None
    start: dict | None = None

    def to_dict(self) -> dict:
        # The optimiser's state is saved under "moments", the key checkpoints have always used,
        # so that checkpoints written before the optimisers became objects still resume.
        return {"method": self.method, "iteration": self.iteration, "z": list(map(float, self.z)),
                "history": self.history,
                "moments": {} if self.solver is None else self.solver.to_dict(),
                **({"start": self.start} if self.start is not None else {})}

    @classmethod
    def from_dict(cls, d: dict) -> "OptimizerState":
        method = str(d["method"])
        moments = dict(d.get("moments", {}))
        solver = get(method).State.from_dict(moments) if moments else None
        return cls(method, int(d["iteration"]), np.asarray(d["z"], np.float64),
                   list(d.get("history", [])), solver, d.get("start"))


Callback = Callable[[OptimizerState], None]


class Optimiser(abc.ABC):
    """An optimiser of a fit's objective over the unconstrained vector ``z``.

    Subclasses set :attr:`State` (a frozen dataclass with ``to_dict`` and a ``from_dict``
    classmethod, JSON-serialisable) and implement :meth:`run`.
    """

    #: The registered name (set by :func:`register`).
    name: ClassVar[str]
    #: The type of :attr:`OptimizerState.solver` for this optimiser.
    State: ClassVar[type]

    @abc.abstractmethod
    def run(self, objective, state: OptimizerState, settings,
            on_iteration: Callback | None = None) -> OptimizerState:
        """Optimise from ``state`` (fresh or resumed) and return where it ended.

        Parameters
        ----------
        objective : abs.fitting.objective.Objective
        state : OptimizerState
        settings : FitSettings
        on_iteration : callable, optional
            Called with the state after every iteration (progress, checkpoints).
        """

    def averaged_points(self, state: OptimizerState) -> np.ndarray | None:
        """Points ``z`` (K, P) whose mean is the answer and whose scatter is the Monte-Carlo part
        of its standard errors; ``None`` when the optimiser does not average."""
        return None

    def scatter_points(self, state: OptimizerState) -> np.ndarray | None:
        """A larger set of iterates for the Monte-Carlo scatter when :meth:`averaged_points`
        holds few (see :func:`abs.fitting.laplace.with_monte_carlo_error`); ``None``: use those."""
        return None

    def sequential_points(self, state: OptimizerState) -> bool:
        """Whether :meth:`averaged_points` are successive iterates (whose Monte-Carlo error needs
        their autocorrelation) rather than independent draws."""
        return False

    def curvatures(self, state: OptimizerState) -> tuple[np.ndarray, np.ndarray] | None:
        """Cross-curvature estimates ``J^T J`` (K, P, P; unconstrained coordinates) the optimiser
        made near its answer, and the points ``z`` (K, P) they were made at, for the Laplace
        approximation to average; ``None`` when it keeps none."""
        return None

    def limited_steps(self, state: OptimizerState) -> np.ndarray | None:
        """Bool (K, P): per step of the averaging phase and coordinate, whether the optimiser's
        own step was cut to a trust radius (read by :func:`abs.fitting.checks.run_checks` through
        ``fit.json``); ``None`` when the optimiser keeps no such record."""
        return None


def register(name: str):
    """Class decorator: register an :class:`Optimiser` subclass under ``name`` (its file's
    name)."""
    def decorate(cls):
        cls.name = name
        _REGISTRY[name] = cls
        return cls
    return decorate


def names() -> tuple[str, ...]:
    """The registered optimisers' names, from the package's files (nothing is imported)."""
    return tuple(sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")))


def get(name: str) -> Optimiser:
    """The optimiser registered under ``name`` (its module is imported on first use).

    Raises
    ------
    ValueError
        No optimiser of that name.
    """
    if name not in _REGISTRY:
        if name not in names():
            raise ValueError(f"unknown optimiser {name!r}; known: {', '.join(names())}")
        importlib.import_module(f"{__name__}.{name}")
    return _REGISTRY[name]()
