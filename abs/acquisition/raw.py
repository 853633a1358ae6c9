"""Reading raw sensor mosaics: a registry of readers by file extension.

A reader returns a :class:`RawFrame`: the undemosaiced mosaic in sensor data numbers (DN), its
white (saturation) level and, when the file says, its Bayer pattern. Single-channel 8/16-bit
TIFF/PNG/PGM mosaics are read with OpenCV; camera raw files (DNG, CR2, NEF, ARW, ...) with rawpy
(LibRaw) when it is installed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["RawFrame", "read_raw", "RAW_READERS"]


@dataclass
class RawFrame:
    """One raw sensor frame.

    Attributes
    ----------
    mosaic : np.ndarray
        ``(H, W)`` float64 sensor values, data numbers (black level not subtracted).
    white_level : float
        Largest value the sensor records (saturation), data numbers.
    black_level : float
        Sensor offset from the file's metadata, data numbers (0 when unknown: use dark frames).
    cfa_pattern : str or None
        Bayer pattern of the top-left 2x2 block (``RGGB`` ...) if the file states it.
    """

    mosaic: np.ndarray
    white_level: float
    black_level: float = 0.0
    cfa_pattern: str | None = None


def _read_opencv_mosaic(path: Path) -> RawFrame:
    pixels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise InputError(path, "", "cannot read this file as a raw mosaic (missing or corrupt)")
    if pixels.ndim != 2:
        raise InputError(path, "", f"expected a single-channel raw mosaic, got {pixels.shape[2]} "
                                   "channels (already demosaiced? pass it as a photograph)")
    if pixels.dtype not in (np.uint8, np.uint16):
        raise InputError(path, "", f"expected 8- or 16-bit integer samples, got {pixels.dtype}")
    return RawFrame(pixels.astype(np.float64), float(np.iinfo(pixels.dtype).max))


def _read_libraw(path: Path) -> RawFrame:
    try:
        import rawpy  # optional: LibRaw bindings
    except ImportError:
        raise InputError(path, "", f"cannot read raw format {path.suffix!r}: rawpy (LibRaw) is "
                                   "not installed (pip install rawpy)") from None
    try:
        with rawpy.imread(str(path)) as raw:
            mosaic = np.array(raw.raw_image_visible, dtype=np.float64)
            colours = "".join(chr(raw.color_desc[i]) for i in raw.raw_pattern.ravel()[:4])
            pattern = colours if set(colours) <= set("RGB") else None
            return RawFrame(mosaic, float(raw.white_level),
                            float(np.mean(raw.black_level_per_channel)), pattern)
    except Exception as exc:  # LibRaw raises its own types for every unreadable file
        raise InputError(path, "", f"LibRaw cannot read this raw file: {exc}") from exc


#: Lower-case file extension -> reader.
RAW_READERS: dict[str, Callable[[Path], RawFrame]] = {
    ".tif": _read_opencv_mosaic, ".tiff": _read_opencv_mosaic, ".png": _read_opencv_mosaic,
    ".pgm": _read_opencv_mosaic,
    ".dng": _read_libraw, ".cr2": _read_libraw, ".cr3": _read_libraw, ".nef": _read_libraw,
    ".arw": _read_libraw, ".raf": _read_libraw, ".orf": _read_libraw, ".rw2": _read_libraw,
}


def read_raw(path: str | Path) -> RawFrame:
    """Read one raw mosaic; an unknown or unreadable format is an :class:`InputError`."""
    path = Path(path)
    reader = RAW_READERS.get(path.suffix.lower())
    if reader is None:
        raise InputError(path, "", f"unreadable raw format {path.suffix!r}; known: "
                                   f"{', '.join(sorted(RAW_READERS))}")
    if not path.is_file():
        raise InputError(path, "", "no such file")
    return reader(path)
