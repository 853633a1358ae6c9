"""The fitted parameters as one flat vector, and the transforms that keep optimisers in bounds.

Renderers take parameters by name and per-channel arrays; optimisers, samplers and the Laplace
approximation take one flat vector. :class:`ParameterVector` is the one layout between them, so
that a fit's covariance, a chain's columns and a diagnosis's Jacobian columns name the same
scalars in the same order.

Optimisers work on an unconstrained vector ``z``; each scalar maps to its physical value by

- ``lower + (upper - lower) * sigmoid(k * z)`` when both bounds are finite (``glass.ior`` in
  [1, 3]); ``k = 1``, unless the parameter's spec gives a ``typical_step``: then ``k`` makes a
  unit step in ``z`` change the starting value by that step,
- ``lower + s * softplus(z)`` when only the lower bound is (absorption >= 0, scale >= 0),
- ``initial + s * z`` when unbounded (pose, environment rotation),

with ``s`` a typical size of a change of that scalar (:func:`typical_step`), so that a unit step
in ``z`` means a comparable change for every parameter: Levenberg-Marquardt damps all directions
alike and Adam takes steps of the same size in every coordinate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.params.names import Parameter

__all__ = ["ParameterVector", "typical_step"]

_STEP_BY_UNIT = {"m": 0.01, "rad": 0.05}  # pose: centimetres and a few degrees


def _softplus(z):
    return np.logaddexp(0.0, z)


def _softplus_inverse(y):
    return y + np.log(-np.expm1(-y))


def _sigmoid(z):
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def typical_step(spec: Parameter, initial: np.ndarray) -> np.ndarray:
    """Typical size of a change of each scalar of ``spec`` (its units), for conditioning."""
    if spec.typical_step is not None:
        return np.full(len(initial), float(spec.typical_step))
    units = [u.strip() for u in spec.unit.split(",")]
    if len(units) == len(initial) and all(u in _STEP_BY_UNIT for u in units):
        return np.array([_STEP_BY_UNIT[u] for u in units])
    base = np.abs(initial - spec.lower) if np.isfinite(spec.lower) else np.abs(initial)
    return np.maximum(base, 0.1)


@dataclass(frozen=True)
class ParameterVector:
    """Named parameters laid out in one flat vector, with bounds and transforms.

    Attributes
    ----------
    names : tuple of str
    sizes : tuple of int
    lower, upper : ndarray
        Physical bounds of every scalar.
    initial : ndarray
        Physical starting values (clipped into the open bounds).
    step : ndarray
        Typical change of every scalar (physical units).
    units : tuple of str
    gain : ndarray
        ``k`` of the sigmoid of scalars bounded on both sides (1 where the spec gives no
        ``typical_step``, so that existing fits keep their conditioning).
    tied : tuple of str
        Per-channel parameters fitted as one value for every channel (one scalar here, expanded
        by :meth:`split` and :meth:`tangents`): an IOR where the data do not resolve dispersion.
    full_sizes : tuple of int
        Each parameter's size in the scene (``sizes`` differs only for tied parameters).
    """

    names: tuple[str, ...]
    sizes: tuple[int, ...]
    lower: np.ndarray
    upper: np.ndarray
    initial: np.ndarray
    step: np.ndarray
    units: tuple[str, ...]
    gain: np.ndarray | None = None
    tied: tuple[str, ...] = ()
    full_sizes: tuple[int, ...] | None = None

    @classmethod
    def build(cls, specs: dict[str, Parameter], names, initial: dict[str, np.ndarray],
              tied=()) -> "ParameterVector":
        """Lay out ``names`` (in order) from their specs and current values; the names in
        ``tied`` (per-channel parameters) take one scalar, starting at their channels' mean."""
        unknown = [n for n in tied if n not in names]
        if unknown:
            raise ValueError(f"tied {unknown} are not among the fitted parameters {list(names)}")
        full_sizes = []
        sizes, lower, upper, start, step, units, gain = [], [], [], [], [], [], []
        for name in names:
            spec = specs[name]
            value = np.asarray(initial[name], np.float64).ravel()
            full_sizes.append(len(value))
            if name in tied:
                if len(value) < 2:
                    raise ValueError(f"{name} has one value: there is nothing to tie")
                value = np.array([value.mean()])
            sizes.append(len(value))
            lo = np.full(len(value), spec.lower)
            hi = np.full(len(value), spec.upper)
            s = typical_step(spec, value)
            # A start on a bound has z = -inf: move it inside by a small fraction of a step.
            value = np.clip(value, lo + 1e-3 * s, hi - 1e-3 * s)
            k = np.ones(len(value))
            if spec.typical_step is not None and np.isfinite(spec.lower) and np.isfinite(spec.upper):
                # d theta / dz at the start = span * k * u (1 - u) = step.
                u = (value - lo) / (hi - lo)
                k = s / ((hi - lo) * u * (1.0 - u))
            lower.append(lo); upper.append(hi); start.append(value); step.append(s)
            units.append(spec.unit); gain.append(k)
        cat = np.concatenate
        return cls(tuple(names), tuple(sizes), cat(lower), cat(upper), cat(start), cat(step),
                   tuple(units), cat(gain), tuple(tied), tuple(full_sizes))

    @property
    def size(self) -> int:
        return int(sum(self.sizes))

    def slices(self) -> dict[str, slice]:
        out, offset = {}, 0
        for name, n in zip(self.names, self.sizes):
            out[name] = slice(offset, offset + n)
            offset += n
        return out

    def split(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        """Physical vector -> ``{name: values}``, each at its size in the scene (a tied
        parameter's one value repeated in every channel)."""
        return {name: self._expand(name, np.asarray(theta[s], np.float64))
                for name, s in self.slices().items()}

    def tangents(self, tangent: np.ndarray, names=None) -> dict[str, np.ndarray]:
        """A direction over the vector -> ``{name: tangent}`` at the scene's sizes, for
        :meth:`abs.render.CompiledScene.render_forward` (a tied parameter moves every channel)."""
        return {name: self._expand(name, np.asarray(tangent[s], np.float64))
                for name, s in self.slices().items() if names is None or name in names}

    def _expand(self, name: str, value: np.ndarray) -> np.ndarray:
        if name not in self.tied:
            return value
        return np.repeat(value, self.full_sizes[self.names.index(name)])

    def labels(self) -> list[str]:
        """One label per scalar: ``glass.absorption[0]``, ``glass.ior (tied)``, ... (no index
        for single scalars)."""
        return [(f"{name} (tied)" if name in self.tied else name) if n == 1 else f"{name}[{i}]"
                for name, n in zip(self.names, self.sizes) for i in range(n)]

    # ----------------------------------------------------------- transforms
    @property
    def _gain(self) -> np.ndarray:
        return np.ones_like(self.step) if self.gain is None else self.gain

    def _kinds(self):
        lo_f, hi_f = np.isfinite(self.lower), np.isfinite(self.upper)
        return lo_f & hi_f, lo_f & ~hi_f, ~lo_f & hi_f

    def to_physical(self, z: np.ndarray) -> np.ndarray:
        """Unconstrained ``z`` -> physical values."""
        z = np.asarray(z, np.float64)
        both, low, high = self._kinds()
        theta = self.initial + self.step * z
        theta = np.where(low, self.lower + self.step * _softplus(z), theta)
        theta = np.where(high, self.upper - self.step * _softplus(-z), theta)
        span = np.where(both, self.upper - self.lower, 1.0)
        return np.where(both, self.lower + span * _sigmoid(self._gain * z), theta)

    def derivative(self, z: np.ndarray) -> np.ndarray:
        """``d theta / d z`` per scalar (the transform is elementwise)."""
        z = np.asarray(z, np.float64)
        both, low, high = self._kinds()
        d = np.array(self.step, np.float64)
        d = np.where(low, self.step * _sigmoid(z), d)
        d = np.where(high, self.step * _sigmoid(-z), d)
        span = np.where(both, self.upper - self.lower, 1.0)
        s = _sigmoid(self._gain * z)
        return np.where(both, span * self._gain * s * (1.0 - s), d)

    def to_unconstrained(self, theta: np.ndarray) -> np.ndarray:
        """Physical values (strictly inside the bounds) -> ``z``."""
        theta = np.asarray(theta, np.float64)
        both, low, high = self._kinds()
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (theta - self.initial) / self.step
            z = np.where(low, _softplus_inverse(np.maximum((theta - self.lower) / self.step, 1e-300)), z)
            z = np.where(high, -_softplus_inverse(np.maximum((self.upper - theta) / self.step, 1e-300)), z)
            span = np.where(both, self.upper - self.lower, 1.0)
            u = np.clip((theta - self.lower) / span, 1e-12, 1 - 1e-12)
            return np.where(both, (np.log(u) - np.log1p(-u)) / self._gain, z)
