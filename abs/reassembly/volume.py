"""CT volumes on disk: a raw file with a small JSON header, or a stack of 16-bit slice images.

Array layout: ``data[k, j, i]`` is the voxel of slice ``k`` (z), row ``j`` (y), column ``i``
(x). The volume frame is right-handed with its origin at the centre of voxel ``[0, 0, 0]``; the
centre of voxel ``[k, j, i]`` is at ``(i * sx, j * sy, k * sz)`` millimetres, ``(sx, sy, sz)``
being the voxel size.

Header (``volume.json``)::

    {"file": "volume.raw", "shape": [nz, ny, nx], "dtype": "uint16",
     "voxel_size_mm": 0.2, "byte_order": "little"}

``voxel_size_mm`` is one number (cubic voxels) or ``[sx, sy, sz]``; ``file`` is relative to the
header; ``byte_order`` is optional (``little``, the default, or ``big``); ``dtype`` is one of
``uint8``, ``uint16``, ``int16``, ``uint32``, ``int32``, ``float32``, ``float64``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abs.errors import InputError, read_json

__all__ = ["Volume", "read_volume", "read_raw_volume", "write_raw_volume", "read_slices",
           "write_slices", "DTYPES"]

DTYPES = ("uint8", "uint16", "int16", "uint32", "int32", "float32", "float64")
SLICE_SUFFIXES = (".tif", ".tiff", ".png")


@dataclass(frozen=True)
class Volume:
    """A CT volume.

    Attributes
    ----------
    data : np.ndarray
        ``(nz, ny, nx)`` densities (any real dtype; grey values as scanned).
    voxel_size_mm : np.ndarray
        ``(3,)`` voxel size ``(sx, sy, sz)`` in millimetres.
    source : Path or None
        The file or folder it was read from.
    """

    data: np.ndarray
    voxel_size_mm: np.ndarray
    source: Path | None = None

    def __post_init__(self):
        size = np.broadcast_to(np.asarray(self.voxel_size_mm, dtype=np.float64), (3,)).copy()
        if not np.all(np.isfinite(size)) or np.any(size <= 0):
            raise InputError(self.source, "voxel_size_mm", f"expected positive sizes, got {size.tolist()}")
        object.__setattr__(self, "voxel_size_mm", size)
        if np.ndim(self.data) != 3:
            raise InputError(self.source, "shape", f"expected a 3-D volume, got shape {list(np.shape(self.data))}")

    @property
    def spacing_zyx(self) -> tuple[float, float, float]:
        """Voxel size in array-axis order ``(sz, sy, sx)``, mm (for ``marching_cubes``)."""
        sx, sy, sz = self.voxel_size_mm
        return float(sz), float(sy), float(sx)

    def index_to_mm(self, index_zyx: np.ndarray) -> np.ndarray:
        """``(n, 3)`` points in the volume frame, mm ``(x, y, z)``, from ``(k, j, i)`` indices."""
        index = np.asarray(index_zyx, dtype=np.float64)
        return index[..., ::-1] * self.voxel_size_mm


def _header_error(path: Path, field: str, message: str) -> InputError:
    return InputError(path, field, message)


def read_raw_volume(header: str | Path) -> Volume:
    """Read a raw volume through its JSON header (see the module docstring).

    Raises
    ------
    InputError
        Missing header or raw file, malformed header (field named), unknown dtype, or a raw
        file whose size does not match ``shape`` and ``dtype``.
    """
    path = Path(header)
    meta = read_json(path, what="volume header")
    for key in ("file", "shape", "dtype", "voxel_size_mm"):
        if key not in meta:
            raise InputError(path, key, "missing")
    shape = meta["shape"]
    if (not isinstance(shape, list) or len(shape) != 3
            or not all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)):
        raise InputError(path, "shape", f"expected 3 positive integers [nz, ny, nx], got {shape!r}")
    dtype = meta["dtype"]
    if dtype not in DTYPES:
        raise InputError(path, "dtype", f"expected one of {', '.join(DTYPES)}, got {dtype!r}")
    order = meta.get("byte_order", "little")
    if order not in ("little", "big"):
        raise InputError(path, "byte_order", f"expected 'little' or 'big', got {order!r}")
    size = meta["voxel_size_mm"]
    try:
        size = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    except (TypeError, ValueError):
        raise InputError(path, "voxel_size_mm", f"expected a number or [sx, sy, sz], got {size!r}") from None
    if not np.all(np.isfinite(size)) or np.any(size <= 0):
        raise InputError(path, "voxel_size_mm", f"expected positive sizes in mm, got {meta['voxel_size_mm']!r}")
    if not isinstance(meta["file"], str):
        raise InputError(path, "file", f"expected a file name, got {meta['file']!r}")
    raw = path.parent / meta["file"]
    if not raw.is_file():
        raise InputError(path, "file", f"raw file {raw} not found")
    dt = np.dtype(dtype).newbyteorder("<" if order == "little" else ">")
    expected = int(np.prod(shape)) * dt.itemsize
    actual = raw.stat().st_size
    if actual != expected:
        raise InputError(path, "file", f"{raw.name} holds {actual} bytes; shape {shape} of {dtype} "
                                       f"needs {expected}")
    data = np.fromfile(raw, dtype=dt).reshape(shape).astype(np.dtype(dtype).newbyteorder("="))
    return Volume(data, size, path)


def write_raw_volume(path: str | Path, volume: Volume | np.ndarray,
                     voxel_size_mm: float | Sequence[float] | None = None) -> Path:
    """Write a volume as ``<stem>.raw`` (little-endian) next to the JSON header ``path``.

    Returns the header path.
    """
    if not isinstance(volume, Volume):
        if voxel_size_mm is None:
            raise ValueError("voxel_size_mm is needed for a bare array")
        volume = Volume(np.asarray(volume), voxel_size_mm)
    data = np.asarray(volume.data)
    if data.dtype.name not in DTYPES:
        raise ValueError(f"dtype {data.dtype} cannot be written; use one of {', '.join(DTYPES)}")
    header = Path(path)
    header.parent.mkdir(parents=True, exist_ok=True)
    raw = header.with_suffix(".raw")
    data.astype(data.dtype.newbyteorder("<"), copy=False).tofile(raw)
    size = volume.voxel_size_mm
    meta = {"file": raw.name, "shape": list(data.shape), "dtype": data.dtype.name,
            "voxel_size_mm": float(size[0]) if np.all(size == size[0]) else size.tolist(),
            "byte_order": "little"}
    header.write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    return header


def read_slices(paths: str | Path | Sequence[str | Path],
                voxel_size_mm: float | Sequence[float]) -> Volume:
    """Read a stack of single-channel 16-bit (or 8-bit) TIFF/PNG slices, slice ``k`` = z index.

    Parameters
    ----------
    paths : folder or list of files
        A folder (its ``.tif``/``.tiff``/``.png`` files, sorted by name) or the slices in order.
    voxel_size_mm : float or (3,)
        Voxel size ``(sx, sy, sz)``, mm (slice images carry none).

    Raises
    ------
    InputError
        No slices, a missing or unreadable file, a colour slice, or slices of different sizes
        or dtypes.
    """
    if isinstance(paths, (str, Path)):
        folder = Path(paths)
        if not folder.is_dir():
            raise InputError(folder, "", "slice folder not found")
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SLICE_SUFFIXES)
        if not files:
            raise InputError(folder, "", f"no slice images ({', '.join(SLICE_SUFFIXES)}) in the folder")
        source = folder
    else:
        files = [Path(p) for p in paths]
        if not files:
            raise InputError(None, "slices", "no slice files given")
        source = files[0].parent
    slices = []
    for f in files:
        img = _read_slice(f)
        if slices and (img.shape != slices[0].shape or img.dtype != slices[0].dtype):
            raise InputError(f, "", f"slice is {img.dtype} {list(img.shape)}, the first slice "
                                    f"({files[0].name}) is {slices[0].dtype} {list(slices[0].shape)}")
        slices.append(img)
    return Volume(np.stack(slices), voxel_size_mm, source)


def _read_slice(path: Path) -> np.ndarray:
    if not path.is_file():
        raise InputError(path, "", "slice file not found")
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            import tifffile

            img = tifffile.imread(path)
        elif suffix == ".png":
            import cv2

            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if img is None:
                raise ValueError("OpenCV could not decode it")
        else:
            raise InputError(path, "", f"unknown slice format; expected {', '.join(SLICE_SUFFIXES)}")
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - any decoder failure is a bad file
        raise InputError(path, "", f"cannot read slice: {exc}") from None
    if img.ndim != 2:
        raise InputError(path, "", f"expected a single-channel slice, got shape {list(img.shape)}")
    if img.dtype.name not in DTYPES:
        raise InputError(path, "", f"unsupported slice dtype {img.dtype}")
    return img


def write_slices(folder: str | Path, volume: Volume, suffix: str = ".tif") -> list[Path]:
    """Write one 16-bit slice per z index (``slice_0000.tif``, ...); values are clipped to uint16."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    data = np.clip(np.rint(np.asarray(volume.data, dtype=np.float64)), 0, 65535).astype(np.uint16)
    paths = []
    for k, img in enumerate(data):
        p = out / f"slice_{k:04d}{suffix}"
        if suffix in (".tif", ".tiff"):
            import tifffile

            tifffile.imwrite(p, img)
        elif suffix == ".png":
            import cv2

            cv2.imwrite(str(p), img)
        else:
            raise ValueError(f"unknown slice format {suffix!r}")
        paths.append(p)
    return paths


def read_volume(path: str | Path, voxel_size_mm: float | Sequence[float] | None = None) -> Volume:
    """A volume from a JSON header (``.json``) or a folder of slices (needs ``voxel_size_mm``)."""
    p = Path(path)
    if p.is_dir():
        if voxel_size_mm is None:
            raise InputError(p, "voxel_size_mm", "a slice folder needs the voxel size (--voxel-size MM)")
        return read_slices(p, voxel_size_mm)
    if not p.exists():
        raise InputError(p, "", "volume not found (expected a JSON header or a folder of slices)")
    return read_raw_volume(p)
