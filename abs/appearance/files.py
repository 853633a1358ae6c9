"""Reading and writing characterisations and geometry maps (formats: docs/appearance.md).

Both are NumPy ``.npz`` archives read with ``allow_pickle=False``: a file a user gives is data,
never code. Every way a file can be wrong is an :class:`abs.errors.InputError` naming the file
and the field (the array's name, or ``meta.<key>`` for the JSON header).

The characterisation format grows compatibly: arrays added later (``blocks`` for the sensor
step, ``phi_sums`` and ``phi_counts`` for the normal step) are optional on reading, so files
written before them still read (the step that needs them then says so), and readers that predate
them ignore them (``np.load`` reads arrays by name).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from abs.appearance.geometry import Geometry
from abs.appearance.statistics import HIST_EDGES, Characterisation
from abs.errors import InputError

__all__ = ["FORMAT", "write_characterisation", "read_characterisation", "write_geometry",
           "read_geometry"]

FORMAT = "abs-appearance-characterisation/1"
GEOMETRY_FORMAT = "abs-appearance-geometry/1"

_PER_CLASS = ("alpha", "lam", "psi")
_OPTIONAL = ("blocks", "phi_sums", "phi_counts")  # added after format /1 was first written


def _meta_array(meta: dict) -> np.ndarray:
    return np.array(json.dumps(meta, sort_keys=True))  # a unicode scalar: no pickle needed


def write_characterisation(path: str | Path, c: Characterisation) -> None:
    """Write ``c`` to ``path`` (``.npz``)."""
    meta = {"format": FORMAT, "renderer": c.renderer, "options": c.options, "design": c.design,
            "classes": list(c.classes), "settings": c.settings}
    np.savez_compressed(path, meta=_meta_array(meta), theta_edges=c.theta_edges, alpha=c.alpha,
                        lam=c.lam, psi=c.psi, counts=c.counts, profiles=c.profiles,
                        profile_counts=c.profile_counts, hist_edges=HIST_EDGES,
                        hist_global=c.hist_global, hist_local=c.hist_local,
                        **{name: getattr(c, name) for name in _OPTIONAL if getattr(c, name) is not None})


def _load(path: Path, what: str) -> dict:
    if not path.is_file():
        raise InputError(path, "", f"{what} not found" if not path.exists() else f"{what} is not a file")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(path, "", f"not a readable .npz {what}: {exc}") from exc


def _meta(path: Path, arrays: dict, expected_format: str) -> dict:
    if "meta" not in arrays:
        raise InputError(path, "meta", "missing")
    try:
        meta = json.loads(str(arrays["meta"]))
    except json.JSONDecodeError as exc:
        raise InputError(path, "meta", f"not valid JSON: {exc}") from exc
    if not isinstance(meta, dict):
        raise InputError(path, "meta", "expected a JSON object")
    if meta.get("format") != expected_format:
        raise InputError(path, "meta.format", f"expected {expected_format!r}, got {meta.get('format')!r}")
    return meta


def _array(path: Path, arrays: dict, name: str, shape: tuple, finite: bool = False) -> np.ndarray:
    """Array ``name`` with ``shape`` (``None`` entries: any size), numeric."""
    if name not in arrays:
        raise InputError(path, name, "missing array")
    a = arrays[name]
    if a.dtype.kind not in "fiu":
        raise InputError(path, name, f"expected numbers, got dtype {a.dtype}")
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        want = "x".join("?" if s is None else str(s) for s in shape)
        raise InputError(path, name, f"expected shape {want}, got {'x'.join(map(str, a.shape))}")
    if finite and not np.isfinite(a).all():
        raise InputError(path, name, "has NaN or infinite values")
    return a


def read_characterisation(path: str | Path) -> Characterisation:
    """Read and check a characterisation file (see docs/appearance.md)."""
    path = Path(path)
    arrays = _load(path, "characterisation file")
    meta = _meta(path, arrays, FORMAT)
    for key, kind in (("renderer", str), ("design", str), ("classes", list), ("options", dict),
                      ("settings", dict)):
        if not isinstance(meta.get(key), kind):
            raise InputError(path, f"meta.{key}", f"expected a JSON {kind.__name__}, got "
                                                  f"{type(meta.get(key)).__name__}")
    classes = tuple(meta["classes"])
    if not classes or not all(isinstance(c, str) for c in classes) or len(set(classes)) < len(classes):
        raise InputError(path, "meta.classes", "expected distinct class names")
    nc = len(classes)
    edges = _array(path, arrays, "theta_edges", (None,), finite=True)
    if len(edges) < 2 or np.any(np.diff(edges) <= 0) or edges[0] < 0 or edges[-1] > np.pi / 2 + 1e-9:
        raise InputError(path, "theta_edges", "expected increasing angles in [0, pi/2] (radians)")
    nb = len(edges) - 1
    counts = _array(path, arrays, "counts", (nc, nb), finite=True)
    if np.any(counts < 0):
        raise InputError(path, "counts", "negative pixel counts")
    stats = {}
    for name in _PER_CLASS:
        a = _array(path, arrays, name, (nc, nb, 3))
        bad = ~np.isfinite(a) & (counts[..., None] > 0)
        if bad.any():
            raise InputError(path, name, "NaN or infinite where the bin has pixels")
        stats[name] = a
    if np.any(stats["alpha"][counts > 0] < 0):
        raise InputError(path, "alpha", "negative energy ratios")
    profile_counts = _array(path, arrays, "profile_counts", (None, nc, nb), finite=True)
    profiles = _array(path, arrays, "profiles", (profile_counts.shape[0], nc, nb, 3))
    hist_edges = _array(path, arrays, "hist_edges", (len(HIST_EDGES),), finite=True)
    if not np.allclose(hist_edges, HIST_EDGES):
        raise InputError(path, "hist_edges", "not the edges this version of abs writes")
    n_hist = len(HIST_EDGES) - 1
    hist_global = _array(path, arrays, "hist_global", (3, n_hist), finite=True)
    hist_local = _array(path, arrays, "hist_local", (nc, 3, n_hist), finite=True)
    blocks = None
    if "blocks" in arrays:  # optional: files from before the sensor step lack it
        blocks = _array(path, arrays, "blocks", (profile_counts.shape[0], None, None, 3))
        if blocks.shape[1] != blocks.shape[2] or blocks.shape[1] < 1:
            raise InputError(path, "blocks", f"expected a square grid of blocks, got "
                                             f"{blocks.shape[1]}x{blocks.shape[2]}")
        if np.isinf(blocks).any():
            raise InputError(path, "blocks", "infinite values (NaN marks an empty block)")
    phi_sums = phi_counts = None
    if "phi_sums" in arrays or "phi_counts" in arrays:  # optional, but only as a pair
        phi_counts = _array(path, arrays, "phi_counts", (profile_counts.shape[0], nc, nb, None),
                            finite=True)
        if np.any(phi_counts < 0):
            raise InputError(path, "phi_counts", "negative pixel counts")
        phi_sums = _array(path, arrays, "phi_sums", phi_counts.shape + (3,), finite=True)
    return Characterisation(meta["renderer"], meta["options"], meta["design"], classes, edges,
                            stats["alpha"], stats["lam"], stats["psi"], counts, profiles,
                            profile_counts, hist_global, hist_local, meta["settings"], blocks,
                            phi_sums, phi_counts)


def write_geometry(path: str | Path, geometry: Geometry) -> None:
    """Write a geometry map (θ, ids, normals, classes) to ``path`` (``.npz``)."""
    np.savez_compressed(path, meta=_meta_array({"format": GEOMETRY_FORMAT,
                                                "classes": list(geometry.classes)}),
                        theta=geometry.theta, ids=geometry.ids, normals=geometry.normals)


def read_geometry(path: str | Path, shape: tuple[int, int] | None = None) -> Geometry:
    """Read a geometry map; ``shape`` (height, width), when given, must match its image's."""
    path = Path(path)
    arrays = _load(path, "geometry file")
    meta = _meta(path, arrays, GEOMETRY_FORMAT)
    classes = meta.get("classes")
    if not isinstance(classes, list) or not all(isinstance(c, str) for c in classes):
        raise InputError(path, "meta.classes", "expected a list of class names")
    ids = _array(path, arrays, "ids", (None, None))
    if ids.dtype.kind not in "iu":
        raise InputError(path, "ids", f"expected integers, got dtype {ids.dtype}")
    if shape is not None and ids.shape != tuple(shape):
        raise InputError(path, "ids", f"shape {ids.shape} differs from the image's {tuple(shape)}")
    if ids.min() < 0 or ids.max() > len(classes):
        raise InputError(path, "ids", f"ids must lie in 0..{len(classes)} (0: no object)")
    theta = _array(path, arrays, "theta", ids.shape)
    on = ids > 0
    if not np.isfinite(theta[on]).all() or np.any(theta[on] < 0) or np.any(theta[on] > np.pi / 2 + 1e-6):
        raise InputError(path, "theta", "object pixels need angles in [0, pi/2] (radians)")
    normals = _array(path, arrays, "normals", ids.shape + (3,))
    return Geometry(theta.astype(np.float32), ids.astype(np.int32), tuple(classes),
                    normals.astype(np.float32))
