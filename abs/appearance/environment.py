"""The lighting of a characterisation: an environment map file, or a constant one."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from abs.errors import InputError

__all__ = ["DEFAULT_ENVIRONMENT", "load_environment"]

DEFAULT_ENVIRONMENT = "polyhaven_hdri_1k/royal_esplanade_1k.hdr"
"""The default lighting, relative to the shared data folder (a real, CC0 outdoor HDR map)."""


def load_environment(spec: str | None) -> tuple[np.ndarray, str]:
    """The lat-long map named by ``spec`` and a description of it for the files.

    Parameters
    ----------
    spec : str or None
        A path to a lat-long ``.exr``/``.hdr`` map (linear RGB, Mitsuba's orientation),
        ``constant:V`` for a uniform map of radiance ``V`` (the closed-form case), or ``None``
        for :data:`DEFAULT_ENVIRONMENT` in the shared data folder.
    """
    from abs.io.images import read_image
    from abs.io.shared_data import shared_data_dir

    if spec is not None and spec.startswith("constant:"):
        try:
            value = float(spec.split(":", 1)[1])
        except ValueError:
            value = float("nan")
        if not np.isfinite(value) or value <= 0:
            raise InputError(None, "--environment", f"constant:V needs a positive number, got {spec!r}")
        return np.full((32, 64, 3), value, np.float32), spec
    path = Path(spec) if spec is not None else shared_data_dir() / DEFAULT_ENVIRONMENT
    if spec is None and not path.is_file():
        raise InputError(path, "--environment", "the default environment needs the shared data "
                                                "folder; pass --environment FILE or constant:V")
    return read_image(path), str(path)
