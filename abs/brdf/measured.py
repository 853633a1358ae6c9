"""The measured-BRDF family behind the PCA basis: MERL tables by material name, from either source.

Two sources give the same kind of table (``(3, 90, 90, 180)`` float32, BRDF in 1/sr, 0 at invalid
or below-horizon entries):

- real MERL ``.binary`` files ``<binary_dir>/<name>.binary`` (:func:`abs.io.merl.read_merl`), for
  users who have the database;
- otherwise the neural fits in the shared data folder (:func:`abs.brdf.nbrdf.nbrdf_table`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from abs.errors import InputError

__all__ = ["STUDY_MATERIALS", "measured_material_names", "measured_table"]

STUDY_MATERIALS: tuple[str, ...] = (
    "blue-rubber",
    "green-metallic-paint",
    "purple-paint",
    "specular-black-phenolic",
)
"""The materials of the structured-light study (issue 6), held out of the default basis."""


def measured_material_names(binary_dir: str | Path | None = None) -> list[str]:
    """Sorted material names: the ``*.binary`` stems of ``binary_dir``, else the neural fits'."""
    if binary_dir is None:
        from abs.brdf.nbrdf import nbrdf_material_names

        return nbrdf_material_names()
    folder = Path(binary_dir)
    if not folder.is_dir():
        raise InputError(folder, "", "MERL folder not found")
    names = sorted(p.stem for p in folder.glob("*.binary"))
    if not names:
        raise InputError(folder, "", "no MERL .binary files in the folder")
    return names


def measured_table(name: str, binary_dir: str | Path | None = None) -> np.ndarray:
    """The table of one material (see the module docstring for the two sources).

    Returns
    -------
    np.ndarray
        float32 array of shape ``(3, 90, 90, 180)``, BRDF in 1/sr.
    """
    if binary_dir is None:
        from abs.brdf.nbrdf import nbrdf_table

        return nbrdf_table(name)
    from abs.io.merl import read_merl

    path = Path(binary_dir) / f"{name}.binary"
    if not path.is_file():
        raise InputError(path, "", f"no MERL file for material {name!r}")
    return read_merl(path)
