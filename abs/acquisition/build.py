"""Building a capture folder from photographs, dark frames and a camera file.

A build file (JSON, data only) lists the views::

    {"cameras": "calibration.json", "cfa_pattern": "RGGB", "white_level": 4095,
     "views": [{"name": "v0", "camera": "left",
                "frames": ["v0_001ms.tif", "v0_002ms.tif"], "exposures_s": [0.001, 0.002],
                "darks": ["dark_001ms.tif", "dark_002ms.tif"], "holdout": false,
                "mask": "v0_mask.png"}]}

Paths are relative to the build file. Each frame is a raw mosaic (see :mod:`.raw`; demosaiced
bilinearly with the file's CFA pattern, else ``cfa_pattern``) or a linear EXR. ``white_level``
(optional, data numbers) replaces the file's own saturation level: a 12- or 14-bit sensor stored
in 16-bit TIFFs saturates at 4095 or 16383, not at the container's 65535. A view's frames
are merged (:func:`merge_brackets`) into data numbers per second, undistorted to the pinhole
camera of :func:`pinhole_K`, and written with :func:`abs.io.capture.save_capture`. ``mask``
(optional): an image of the photographs' size, drawn on the *original* (distorted) frames,
nonzero where pixels are compared; it is undistorted with the image (nearest neighbour, and
pixels that fall outside the original frame are left out) and written as the view's mask.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from abs.acquisition.camera_file import read_camera_file
from abs.acquisition.demosaic import cfa_masks, demosaic_bilinear
from abs.acquisition.hdr import MergedHDR, merge_brackets
from abs.acquisition.raw import read_raw
from abs.acquisition.undistort import pinhole_K, undistort_image, undistort_mask
from abs.errors import InputError
from abs.io.capture import Capture, save_capture
from abs.io.images import read_image, read_mask

__all__ = ["build_capture", "load_frame"]

_VIEW_KEYS = {"name", "camera", "frames", "exposures_s", "darks", "holdout", "mask"}


def load_frame(path: Path, cfa_pattern: str | None, saturation: float = 0.95,
               white_level: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One frame as ``(H, W, 3)`` linear values (data numbers) and its saturation mask.

    Raw mosaics are demosaiced bilinearly (CFA pattern from the file, else ``cfa_pattern``), with
    the black level subtracted. A demosaiced pixel is saturated when any mosaic site within its
    3x3 neighbourhood (the bilinear kernels' support) of the same colour is at or above
    ``saturation`` times the white level (``white_level`` if given, else the file's):
    interpolation would otherwise hide a clipped neighbour (at the border, reflected bilinear
    gives half a clipped value). EXR files are taken as already linear RGB, never
    saturated.
    """
    if path.suffix.lower() == ".exr":
        rgb = read_image(path).astype(np.float64)
        return rgb, np.zeros(rgb.shape, bool)
    frame = read_raw(path)
    pattern = frame.cfa_pattern or cfa_pattern
    if pattern is None:
        raise InputError(path, "cfa_pattern", "the file does not state its Bayer pattern; give "
                                              "cfa_pattern (RGGB, BGGR, GRBG or GBRG)")
    white = frame.white_level if white_level is None else float(white_level)
    clipped = frame.mosaic >= saturation * white
    sites = cfa_masks(frame.mosaic.shape, pattern)
    near_clipped = np.stack([cv2.dilate((clipped & sites[..., c]).astype(np.uint8),
                                        np.ones((3, 3), np.uint8)).astype(bool)
                             for c in range(3)], axis=-1)
    rgb = demosaic_bilinear(frame.mosaic - frame.black_level, pattern).astype(np.float64)
    return rgb, near_clipped


def _view_hdr(entry: dict[str, Any], folder: Path, cfa: str | None, source: Path,
              field: str, white_level: float | None = None) -> MergedHDR:
    frames = entry["frames"]
    if not isinstance(frames, list) or not frames:
        raise InputError(source, f"{field}.frames", "expected a non-empty list of files")
    exposures = entry.get("exposures_s", [1.0] * len(frames) if len(frames) == 1 else None)
    if not isinstance(exposures, list) or len(exposures) != len(frames):
        raise InputError(source, f"{field}.exposures_s", f"expected {len(frames)} exposure times "
                                                         "(seconds), one per frame")
    loaded = [load_frame(folder / f, cfa, white_level=white_level) for f in frames]
    shapes = {img.shape for img, _ in loaded}
    if len(shapes) > 1:
        raise InputError(source, f"{field}.frames", f"mixed image sizes {sorted(shapes)}")
    darks = None
    if entry.get("darks") is not None:
        if not isinstance(entry["darks"], list) or len(entry["darks"]) != len(frames):
            raise InputError(source, f"{field}.darks", f"expected {len(frames)} dark frames, one "
                                                       "per frame (the same file may repeat)")
        darks = [load_frame(folder / f, cfa)[0] for f in entry["darks"]]
        for f, d in zip(entry["darks"], darks):
            if d.shape != loaded[0][0].shape:
                raise InputError(folder / f, "", f"dark frame is {d.shape[1]}x{d.shape[0]}, "
                                                 f"frames {loaded[0][0].shape[1]}x"
                                                 f"{loaded[0][0].shape[0]}: mixed image sizes")
    return merge_brackets([img for img, _ in loaded], exposures, np.inf, darks,
                          saturated=[sat for _, sat in loaded], source=f"{source}: {field}")


def build_capture(build_file: str | Path, out: str | Path,
                  progress: Callable[[int], None] | None = None) -> tuple[Capture,
                                                                          dict[str, MergedHDR]]:
    """Build a capture folder from a build file (format in the module docstring).

    Returns
    -------
    Capture
        The written capture, as :func:`abs.io.capture.load_capture` reads it.
    dict of str to MergedHDR
        The merge of each view (weight maps for the report).
    """
    source = Path(build_file)
    try:
        spec = json.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(source, "", "no such build file") from None
    except json.JSONDecodeError as exc:
        raise InputError(source, "", f"not valid JSON: {exc.msg} at line {exc.lineno}") from exc
    folder = source.parent
    if not isinstance(spec, dict) or "cameras" not in spec or "views" not in spec:
        raise InputError(source, "", "expected an object with 'cameras' and 'views'")
    cameras = read_camera_file(folder / spec["cameras"])
    cfa = spec.get("cfa_pattern")
    white_level = spec.get("white_level")
    if white_level is not None and (isinstance(white_level, bool)
                                    or not isinstance(white_level, (int, float))
                                    or not white_level > 0):
        raise InputError(source, "white_level", f"expected a positive number of data numbers, "
                                                f"got {white_level!r}")
    views, images, masks, merges = [], {}, {}, {}
    for i, entry in enumerate(spec["views"]):
        field = f"views[{i}]"
        if not isinstance(entry, dict):
            raise InputError(source, field, "expected an object")
        unknown = sorted(set(entry) - _VIEW_KEYS)
        if unknown:
            raise InputError(source, f"{field}.{unknown[0]}", f"unknown key; allowed: "
                                                             f"{', '.join(sorted(_VIEW_KEYS))}")
        for key in ("name", "camera", "frames"):
            if key not in entry:
                raise InputError(source, f"{field}.{key}", "missing")
        if entry["camera"] not in cameras:
            raise InputError(source, f"{field}.camera", f"{entry['camera']!r} is not in the "
                                                        f"camera file; known: "
                                                        f"{', '.join(sorted(cameras))}")
        cam = cameras[entry["camera"]]
        merged = _view_hdr(entry, folder, cfa, source, field, white_level)
        if merged.radiance.shape[:2] != (cam.height, cam.width):
            raise InputError(source, f"{field}.frames", f"images are {merged.radiance.shape[1]}x"
                                                        f"{merged.radiance.shape[0]}, camera "
                                                        f"{entry['camera']} is {cam.width}x"
                                                        f"{cam.height}: mixed image sizes")
        K_new = pinhole_K(cam)
        images[entry["name"]] = undistort_image(merged.radiance, cam, K_new)
        if entry.get("mask") is not None:
            mask = read_mask(folder / entry["mask"], (cam.height, cam.width))
            masks[entry["name"]] = undistort_mask(mask, cam, K_new)
        views.append({"name": entry["name"], "K": K_new, "R": cam.R, "t": cam.t,
                      "holdout": bool(entry.get("holdout", False))})
        merges[entry["name"]] = merged
        if progress is not None:
            progress(1)
    return save_capture(out, views, images, masks or None), merges
