"""The colour-correction file (JSON) written by ``abs colour calibrate`` and read by ``apply``.

Layout (all matrices row-major lists)::

    {
      "format": "abs-colour-correction", "version": 1,
      "model": "root-polynomial" | "linear", "degree": 2,
      "terms": ["R", "G", "B", "sqrt(R*G)", "sqrt(G*B)", "sqrt(R*B)"],
      "rgb_to_xyz": [[...6 numbers], x3],      # XYZ = rgb_to_xyz @ terms(camera RGB)
      "white_xyz": [Xw, Yw, Zw],               # reference white (CIELAB, adaptation)
      "space": "CIE RGB", "adaptation": "Bradford",
      "xyz_to_rgb": [[3 numbers], x3],         # output RGB = xyz_to_rgb @ XYZ
      "delta_e00": {"before": [...], "after": [...],            # per patch, training set
                    "before_mean": m, "before_sd": s, "after_mean": m, "after_sd": s},
      "inputs": {...}                          # where the patches and references came from
    }

"before" is the least-squares fit, "after" the ΔE00-refined one (equal when not refined); sd is
the sample standard deviation over patches.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from abs.colour.correction import OUTPUT_SPACES, ColourCorrection
from abs.errors import InputError, read_json

__all__ = ["FORMAT", "TERMS", "correction_to_dict", "write_correction", "read_correction"]

FORMAT = "abs-colour-correction"
#: Names of the expansion terms, in colour-science's order, per degree.
TERMS = {1: ["R", "G", "B"], 2: ["R", "G", "B", "sqrt(R*G)", "sqrt(G*B)", "sqrt(R*B)"]}


def _stats(values: np.ndarray) -> tuple[float, float]:
    v = np.asarray(values, np.float64)
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else 0.0


def correction_to_dict(correction: ColourCorrection, inputs: dict | None = None) -> dict:
    """The JSON-ready dictionary of a correction (layout in the module docstring)."""
    bm, bs = _stats(correction.delta_e_before)
    am, as_ = _stats(correction.delta_e_after)
    return {
        "format": FORMAT, "version": 1,
        "model": "linear" if correction.degree == 1 else "root-polynomial",
        "degree": correction.degree, "terms": TERMS[correction.degree],
        "rgb_to_xyz": correction.matrix.tolist(), "white_xyz": correction.white_xyz.tolist(),
        "space": correction.space, "adaptation": "Bradford",
        "xyz_to_rgb": correction.xyz_to_rgb.tolist(),
        "delta_e00": {"before": correction.delta_e_before.tolist(),
                      "after": correction.delta_e_after.tolist(),
                      "before_mean": bm, "before_sd": bs, "after_mean": am, "after_sd": as_},
        "inputs": inputs or {},
    }


def write_correction(path: str | Path, correction: ColourCorrection, inputs: dict | None = None) -> None:
    """Write a correction file (see the module docstring)."""
    Path(path).write_text(json.dumps(correction_to_dict(correction, inputs), indent=2) + "\n")


def _matrix(doc: dict, key: str, shape: tuple[int, int], source: str) -> np.ndarray:
    try:
        m = np.array(doc[key], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(source, key, "missing or not a matrix of numbers") from exc
    if m.shape != shape or not np.all(np.isfinite(m)):
        raise InputError(source, key, f"expected a finite {shape[0]}x{shape[1]} matrix, got shape {m.shape}")
    return m


def read_correction(path: str | Path) -> ColourCorrection:
    """Read a correction file; errors name the file and field."""
    source = str(path)
    doc = read_json(path, what="colour correction file")
    if doc.get("format") != FORMAT:
        raise InputError(source, "format", f"expected {FORMAT!r}")
    degree = doc.get("degree")
    if degree not in TERMS:
        raise InputError(source, "degree", f"expected 1 or 2, got {degree!r}")
    if doc.get("space") not in OUTPUT_SPACES:
        raise InputError(source, "space", f"expected one of {OUTPUT_SPACES}")
    de = doc.get("delta_e00", {})
    return ColourCorrection(degree, _matrix(doc, "rgb_to_xyz", (3, len(TERMS[degree])), source),
                            _matrix({"white_xyz": [doc.get("white_xyz")]}, "white_xyz", (1, 3), source)[0],
                            doc["space"], _matrix(doc, "xyz_to_rgb", (3, 3), source),
                            np.array(de.get("before", []), np.float64),
                            np.array(de.get("after", []), np.float64))
