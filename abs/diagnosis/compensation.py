"""Compensation made visible: how the parameters fitted before an effect was added moved when it
was added.

A fitted parameter can soak up an effect the model leaves out: a glass absorption fitted too
high makes up for a cloth that is too bright in the model. Once the effect is added and fitted,
such a parameter moves back. The move is measured in the **reference fit's** standard errors
(the fit without the effect, :attr:`abs.fitting.FitResult.uncertainty`): that fit claimed its
value to within one standard error, so a move beyond it is more than the fit's own uncertainty
explains, and the parameter is flagged as having compensated for the missing effect.

The reference is the round's control fit (the model without the effect, refitted with the same
settings and starting values as the extended model, :mod:`abs.diagnosis.select`), so a move is
the effect's doing rather than a better-converged refit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Shift", "FLAG_STDERR", "parameter_shifts", "describe_shifts"]

#: A baseline parameter that moves by more than this many of its standard errors is flagged.
FLAG_STDERR = 1.0


@dataclass(frozen=True)
class Shift:
    """One baseline parameter before and after an effect was added.

    Attributes
    ----------
    parameter : str
        Its name (``environment.scale``).
    before, after : ndarray
        Fitted values without and with the effect (the parameter's units), one per scalar.
    stderr : ndarray
        Standard errors of ``before`` (same units); NaN where the reference fit could not
        determine the scalar.
    """

    parameter: str
    before: np.ndarray
    after: np.ndarray
    stderr: np.ndarray

    @property
    def in_stderr(self) -> np.ndarray:
        """``(after - before) / stderr`` per scalar; NaN where the standard error is unknown."""
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (self.after - self.before) / self.stderr
        return np.where(np.isfinite(self.stderr) & (self.stderr > 0), z, np.nan)

    @property
    def compensating(self) -> bool:
        """Some scalar moved by more than :data:`FLAG_STDERR` standard errors."""
        z = self.in_stderr
        return bool(np.any(np.abs(z[np.isfinite(z)]) > FLAG_STDERR))

    def to_json(self) -> dict:
        def finite(values):
            return [float(v) if np.isfinite(v) else None for v in values]

        return {"parameter": self.parameter, "before": finite(self.before),
                "after": finite(self.after), "stderr": finite(self.stderr),
                "shift_in_stderr": [None if not np.isfinite(z) else round(float(z), 3)
                                    for z in self.in_stderr],
                "compensating": self.compensating}


def parameter_shifts(before: dict, stderr: dict, after: dict) -> list[Shift]:
    """The shifts of every parameter fitted both without and with the effect.

    Parameters
    ----------
    before : dict of str to array-like
        Fitted values of the reference model (without the effect).
    stderr : dict of str to array-like
        Their standard errors (NaN where not identifiable); parameters without an entry (held
        at a short fit's value, not fitted) are left out.
    after : dict of str to array-like
        Fitted values of the model with the effect (its own parameters are not in ``before``,
        so they are left out).
    """
    return [Shift(name, np.asarray(before[name], float).ravel(), np.asarray(after[name], float).ravel(),
                  np.asarray(stderr[name], float).ravel())
            for name in before if name in stderr and name in after]


def _values(v: np.ndarray) -> str:
    return "/".join(f"{x:.4g}" for x in v)


def describe_shifts(shifts: list[Shift]) -> str:
    """A sentence naming the flagged (compensating) parameters; empty when none is."""
    flagged = [s for s in shifts if s.compensating]
    if not flagged:
        return ""
    parts = []
    for s in flagged:
        z = s.in_stderr
        parts.append(f"{s.parameter} from {_values(s.before)} to {_values(s.after)} "
                     f"({', '.join('n/a' if not np.isfinite(x) else f'{x:+.1f}' for x in z)} "
                     f"standard errors)")
    verb = "was" if len(flagged) == 1 else "were"
    return (f"Adding it moved {'; '.join(parts)}: more than the fit without it could explain, so "
            f"{'that parameter' if len(flagged) == 1 else 'those parameters'} {verb} compensating "
            f"for the missing effect.")
