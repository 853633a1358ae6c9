"""The camera file: calibrated cameras with distortion, as JSON (written by ``abs calibrate``).

Format (version 1)::

    {"format": "abs-cameras", "version": 1,
     "cameras": {"left": {"width": 640, "height": 512,
                          "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
                          "distortion": [k1, k2, p1, p2, k3],
                          "R": [[...], [...], [...]], "t": [tx, ty, tz],
                          "rms_px": 0.15}}}

- ``K``: pixels, pixel centres at integers (docs/conventions.md). ``distortion``: OpenCV's
  Brown-Conrady coefficients in OpenCV's order (4, 5, 8, 12 or 14 numbers).
- ``R``, ``t`` (optional, default identity and zero): world-to-camera, ``x_cam = R X + t``,
  metres. Stereo calibration puts the first camera at the origin; extrinsic calibration puts the
  world on the board.
- ``rms_px`` and keys starting with ``_`` are informative only.

:func:`abs.acquisition.undistort.pinhole_camera` turns one entry into the capture contract's
distortion-free camera.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from abs.errors import InputError, read_json

__all__ = ["CameraModel", "read_camera_file", "write_camera_file", "FORMAT_NAME"]

FORMAT_NAME = "abs-cameras"
_KEYS = {"width", "height", "K", "distortion", "R", "t", "rms_px"}


@dataclass
class CameraModel:
    """One calibrated camera with lens distortion.

    Attributes
    ----------
    width, height : int
        Image size, pixels.
    K : np.ndarray
        (3, 3) camera matrix, pixels.
    distortion : np.ndarray
        OpenCV distortion coefficients ``k1, k2, p1, p2[, k3, ...]``.
    R : np.ndarray
        (3, 3) world-to-camera rotation.
    t : np.ndarray
        (3,) world-to-camera translation, metres.
    rms_px : float or None
        Calibration RMS reprojection error, pixels (informative).
    """

    width: int
    height: int
    K: np.ndarray
    distortion: np.ndarray
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rms_px: float | None = None


def _array(value: Any, shape: tuple[int, ...] | None, source: Path, where: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(source, where, f"expected numbers, got {value!r}") from None
    if shape is not None and arr.shape != shape:
        raise InputError(source, where, f"expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(source, where, "values must be finite")
    return arr


def _parse_camera(entry: Any, source: Path, where: str) -> CameraModel:
    if not isinstance(entry, dict):
        raise InputError(source, where, f"expected an object, got {type(entry).__name__}")
    unknown = sorted(k for k in entry if k not in _KEYS and not k.startswith("_"))
    if unknown:
        raise InputError(source, f"{where}.{unknown[0]}", f"unknown key; allowed: "
                                                         f"{', '.join(sorted(_KEYS))}")
    for key in ("width", "height", "K", "distortion"):
        if key not in entry:
            raise InputError(source, f"{where}.{key}", "missing")
    for key in ("width", "height"):
        if not isinstance(entry[key], int) or entry[key] <= 0:
            raise InputError(source, f"{where}.{key}", f"expected a positive integer, got "
                                                      f"{entry[key]!r}")
    K = _array(entry["K"], (3, 3), source, f"{where}.K")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise InputError(source, f"{where}.K", "expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] "
                                               f"with fx, fy > 0, got {K.tolist()}")
    dist = _array(entry["distortion"], None, source, f"{where}.distortion").ravel()
    if dist.size not in (4, 5, 8, 12, 14):
        raise InputError(source, f"{where}.distortion", f"expected 4, 5, 8, 12 or 14 OpenCV "
                                                        f"coefficients, got {dist.size}")
    R = _array(entry.get("R", np.eye(3).tolist()), (3, 3), source, f"{where}.R")
    if np.max(np.abs(R.T @ R - np.eye(3))) > 1e-5 or abs(np.linalg.det(R) - 1) > 1e-5:
        raise InputError(source, f"{where}.R", "not a rotation (orthonormal, det +1)")
    t = _array(entry.get("t", [0.0, 0.0, 0.0]), (3,), source, f"{where}.t")
    rms = entry.get("rms_px")
    return CameraModel(entry["width"], entry["height"], K, dist, R, t,
                       None if rms is None else float(rms))


def read_camera_file(path: str | Path) -> dict[str, CameraModel]:
    """Read a camera file; errors name the file and the field (``cameras.left.K``)."""
    path = Path(path)
    data = read_json(path, what="camera file")
    if data.get("format") != FORMAT_NAME:
        raise InputError(path, "format", f"expected \"{FORMAT_NAME}\" (a camera file written by "
                                         "abs calibrate)")
    if data.get("version") != 1:
        raise InputError(path, "version", f"unsupported version {data.get('version')!r}; "
                                          "expected 1")
    cameras = data.get("cameras")
    if not isinstance(cameras, dict) or not cameras:
        raise InputError(path, "cameras", "expected a non-empty object of named cameras")
    return {name: _parse_camera(entry, path, f"cameras.{name}") for name, entry in cameras.items()}


def write_camera_file(path: str | Path, cameras: dict[str, CameraModel]) -> None:
    """Write cameras to ``path`` (merging into nothing: the file is replaced)."""
    out: dict[str, Any] = {}
    for name, cam in cameras.items():
        entry: dict[str, Any] = {"width": int(cam.width), "height": int(cam.height),
                                 "K": np.asarray(cam.K, float).tolist(),
                                 "distortion": np.ravel(cam.distortion).astype(float).tolist(),
                                 "R": np.asarray(cam.R, float).tolist(),
                                 "t": np.ravel(cam.t).astype(float).tolist()}
        if cam.rms_px is not None:
            entry["rms_px"] = float(cam.rms_px)
        out[name] = entry
    text = json.dumps({"format": FORMAT_NAME, "version": 1, "cameras": out}, indent=2)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(text + "\n", encoding="utf-8")
