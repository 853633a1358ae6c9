"""An LED's radial attenuation profile: relative intensity as a function of the angle off its axis.

The thesis calibrates this profile per LED from a grey-board capture (issue 27, part 3, not built
here); the geometry file carries it either as a power of the cosine, the usual model of a
lensed LED, or as a table measured at a few angles and interpolated linearly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Attenuation"]


@dataclass(frozen=True)
class Attenuation:
    """Relative intensity of an LED off its axis, 1 on the axis.

    Parameters
    ----------
    exponent : float or None
        ``cos(theta)**exponent`` profile (theta off the axis); ``None`` when ``table_deg`` is used.
    table_deg : tuple of float
        Angles off the axis, degrees, increasing, for a tabulated profile.
    table_values : tuple of float
        Relative intensity at ``table_deg`` (dimensionless); 0 beyond the last angle.
    """

    exponent: float | None = 4.0
    table_deg: tuple[float, ...] = ()
    table_values: tuple[float, ...] = ()

    def __call__(self, cos_off_axis: np.ndarray) -> np.ndarray:
        """Relative intensity (dimensionless) at ``cos(theta)`` off the axis; 0 behind the LED."""
        c = np.clip(np.asarray(cos_off_axis, dtype=np.float64), -1.0, 1.0)
        if self.exponent is not None:
            return np.where(c > 0.0, np.clip(c, 0.0, 1.0) ** self.exponent, 0.0)
        angle = np.rad2deg(np.arccos(c))
        return np.interp(angle, self.table_deg, self.table_values, right=0.0)

    def to_dict(self) -> dict:
        if self.exponent is not None:
            return {"kind": "cos_power", "exponent": self.exponent}
        return {"kind": "table", "angles_deg": list(self.table_deg), "values": list(self.table_values)}
