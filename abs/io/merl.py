"""Read and write isotropic BRDF tables in the MERL ``.binary`` layout.

The layout (see ``shared/data/merl_nbrdf/FORMAT.md`` sections 5 and 6): a header of three
little-endian int32 ``(90, 90, 180)`` = (n_θh, n_θd, n_φd), then ``3 * 90 * 90 * 180`` float64
in C order ``[channel][θh][θd][φd]``, channels R, G, B. A stored value times the channel's
scale (:data:`MERL_SCALE`) is the BRDF in 1/sr. Negative stored values mark invalid entries
(configurations below the horizon or not measured).

Sample positions (index ``i``, ``j``, ``k``):

- θh(i) = (i / 90)² · π/2 (denser near the specular peak),
- θd(j) = j / 90 · π/2,
- φd(k) = k / 180 · π (only [0, π) is stored; reciprocity gives f(φd) = f(φd + π)).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from abs.errors import InputError

__all__ = [
    "MERL_SHAPE",
    "MERL_SIZE",
    "MERL_SCALE",
    "read_merl",
    "write_merl",
    "merl_sample_angles",
]

MERL_SHAPE: tuple[int, int, int, int] = (3, 90, 90, 180)
"""Array shape of a table: (channel, θh index, θd index, φd index)."""
MERL_SIZE: int = 3 * 90 * 90 * 180
"""Number of BRDF values in a table (all channels)."""
MERL_SCALE: tuple[float, float, float] = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
"""Per-channel factors (R, G, B) from stored values to BRDF values in 1/sr."""

_HEADER = np.array(MERL_SHAPE[1:], dtype="<i4")
_HEADER_BYTES = _HEADER.nbytes
_FILE_BYTES = _HEADER_BYTES + 8 * MERL_SIZE


def _scales() -> np.ndarray:
    return np.asarray(MERL_SCALE, dtype=np.float64).reshape(3, 1, 1, 1)


def read_merl(path: str | Path) -> np.ndarray:
    """Read a MERL ``.binary`` BRDF table.

    Parameters
    ----------
    path : str or Path
        The ``.binary`` file.

    Returns
    -------
    np.ndarray
        float32 array of shape ``(3, 90, 90, 180)`` (R/G/B, θh, θd, φd): the BRDF in 1/sr, the
        MERL scales applied. Invalid entries (negative in the file) are returned as ``0``, the
        value MERL's own reader evaluates them to, so that the table can be interpolated and
        rendered without special cases.

    Raises
    ------
    InputError
        When the file cannot be read, has the wrong size or header, or holds NaN/inf values.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputError(path, "", f"cannot read MERL file: {err.strerror or err}") from err
    if len(raw) < _HEADER_BYTES:
        raise InputError(path, "header", f"file is {len(raw)} bytes, too short for the 12-byte header")
    header = np.frombuffer(raw, dtype="<i4", count=3)
    if not np.array_equal(header, _HEADER):
        raise InputError(
            path, "header", f"expected dimensions (90, 90, 180), got {tuple(int(v) for v in header)}"
        )
    if len(raw) != _FILE_BYTES:
        raise InputError(
            path,
            "data",
            f"expected {_FILE_BYTES} bytes (header + {MERL_SIZE} float64), got {len(raw)}",
        )
    stored = np.frombuffer(raw, dtype="<f8", offset=_HEADER_BYTES).reshape(MERL_SHAPE)
    bad = ~np.isfinite(stored)
    if bad.any():
        first = tuple(int(v) for v in np.argwhere(bad)[0])
        raise InputError(
            path, "data", f"{int(bad.sum())} non-finite values, first at [channel, θh, θd, φd] = {first}"
        )
    # Scale in float64 before the cast so that the scales are applied at full precision.
    brdf = np.maximum(stored, 0.0) * _scales()
    return brdf.astype(np.float32)


def write_merl(path: str | Path, brdf: np.ndarray) -> None:
    """Write a BRDF table as a MERL ``.binary`` file (inverse of :func:`read_merl`).

    Parameters
    ----------
    path : str or Path
        Destination file; overwritten if it exists.
    brdf : np.ndarray
        BRDF values in 1/sr, shape ``(3, 90, 90, 180)`` or flat ``(3*90*90*180,)`` in MERL order.
        Negative values are written as they are (MERL's "invalid" marker once divided by the scale).

    Raises
    ------
    InputError
        When ``brdf`` has the wrong number of values or holds NaN/inf.
    """
    values = np.asarray(brdf, dtype=np.float64)
    if values.shape not in (MERL_SHAPE, (MERL_SIZE,)):
        raise InputError(None, "brdf", f"expected shape {MERL_SHAPE} or ({MERL_SIZE},), got {values.shape}")
    if not np.isfinite(values).all():
        raise InputError(None, "brdf", "holds NaN or infinite values")
    stored = (values.reshape(MERL_SHAPE) / _scales()).astype("<f8")
    with open(path, "wb") as file:
        file.write(_HEADER.tobytes())
        file.write(stored.tobytes(order="C"))


def merl_sample_angles() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rusinkiewicz angles of the table's sample positions, in radians.

    Returns
    -------
    theta_h, theta_d, phi_d : np.ndarray
        float64 arrays of shape ``(90, 90, 180)`` each (θh, θd, φd index order), broadcast
        from the 1-D sample positions so they can be used directly with a single channel.
    """
    theta_h = (np.arange(90) / 90.0) ** 2 * (np.pi / 2)
    theta_d = np.arange(90) / 90.0 * (np.pi / 2)
    phi_d = np.arange(180) / 180.0 * np.pi
    grids = np.meshgrid(theta_h, theta_d, phi_d, indexing="ij")
    return grids[0], grids[1], grids[2]
