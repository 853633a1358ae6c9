"""One view of a fit as the report shows it: the photograph and the renderings before and after."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.errors import InputError

__all__ = ["ReportView"]


@dataclass(frozen=True)
class ReportView:
    """A photograph with its renderings at the initial and at the fitted parameters.

    Parameters
    ----------
    name : str
        View name, as in the capture's ``cameras.json``.
    holdout : bool
        True for a view left out of the fit (it only checks the result).
    photograph : np.ndarray
        ``(height, width, 3)`` linear RGB.
    before : np.ndarray
        Rendering with the initial parameters, same shape and units.
    after : np.ndarray
        Rendering with the fitted parameters, same shape and units.

    Raises
    ------
    InputError
        If an image is not ``(height, width, 3)`` or the three shapes differ.
    """

    name: str
    holdout: bool
    photograph: np.ndarray
    before: np.ndarray
    after: np.ndarray

    def __post_init__(self) -> None:
        shape = np.shape(self.photograph)
        if len(shape) != 3 or shape[2] != 3:
            raise InputError(None, f"views.{self.name}.photograph",
                             f"expected an array of shape (height, width, 3), got {shape}")
        for field in ("before", "after"):
            if np.shape(getattr(self, field)) != shape:
                raise InputError(None, f"views.{self.name}.{field}",
                                 f"shape {np.shape(getattr(self, field))} differs from the "
                                 f"photograph's {shape}")
