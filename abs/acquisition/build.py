"""Building a capture folder from photographs, dark frames and a camera file.

A build file (JSON, data only) lists the views::

    {"cameras": "calibration.json", "cfa_pattern": "RGGB", "white_level": 4095,
     "demosaic": "bilinear",
     "views": [{"name": "v0", "camera": "left",
                "frames": ["v0_001ms.tif", "v0_002ms.tif"], "exposures_s": [0.001, 0.002],
                "darks": ["dark_001ms.tif", "dark_002ms.tif"], "holdout": false,
                "mask": "v0_mask.png"}]}

Paths are relative to the build file. Each frame is a raw mosaic (see :mod:`.raw`; demosaiced
with the file's CFA pattern, else ``cfa_pattern``) or a linear EXR. ``demosaic`` (optional):
``"bilinear"`` (default, full resolution) or ``"superpixel"`` (one RGB pixel per 2x2 CFA cell, no
interpolation: frames, darks and the camera must have an even width and height, EXR frames are
refused, the capture is half-size and its cameras are :func:`superpixel_camera`'s, masks keep a
superpixel when all four of its pixels are kept). ``white_level``
(optional, data numbers) replaces the file's own saturation level: a 12- or 14-bit sensor stored
in 16-bit TIFFs saturates at 4095 or 16383, not at the container's 65535. A view's frames
are merged (:func:`merge_brackets`) into data numbers per second, undistorted to the pinhole
camera of :func:`pinhole_K`, and written with :func:`abs.io.capture.save_capture`. ``mask``
(optional): an image of the photographs' size, drawn on the *original* (distorted) frames,
nonzero where pixels are compared; it is undistorted with the image (nearest neighbour, and
pixels that fall outside the original frame are left out) and written as the view's mask.
``lens_blur_px`` (optional, sensor pixels, default 0): the standard deviation of the lens's
Gaussian point-spread function, if measured; the build cannot know it and only records it.
The capture's ``processing`` records, per view, the sensor's calibrated camera, the demosaicing
method, the CFA pattern and the lens blur, so that fits render each built pixel as the average of exactly the
sensor sites it was made from (:mod:`abs.acquisition.footprint`). Its ``blur_px`` is the blur that
this demosaicing and undistortion add (:func:`abs.acquisition.blur.processing_blur`, its variance
averaged over the views): what readers that ignore ``processing`` blur their renderings by.
Its ``noise`` (views of raw frames only) is each merged photograph's shot and read noise
(:attr:`abs.acquisition.hdr.MergedHDR.variance`) undistorted with it: fits weigh pixels by it,
so that bright glints, whose noise grows with their light, do not outweigh the rest.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from abs.acquisition.blur import processing_blur
from abs.acquisition.camera_file import read_camera_file
from abs.acquisition.demosaic import (DEMOSAIC_METHODS, cfa_masks, demosaic_bilinear,
                                      demosaic_superpixel, superpixel_any, superpixel_mask)
from abs.acquisition.hdr import MergedHDR, merge_brackets
from abs.acquisition.raw import read_raw
from abs.acquisition.undistort import (pinhole_K, superpixel_camera, undistort_image,
                                       undistort_mask)
from abs.errors import InputError, read_json
from abs.io.capture import Capture, SensorProcessing, lens_blur_px, save_capture
from abs.io.images import read_image, read_mask

__all__ = ["build_capture", "load_frame"]

_VIEW_KEYS = {"name", "camera", "frames", "exposures_s", "darks", "holdout", "mask"}
# (Data numbers per second)^2: a floor on the noise written, which must be positive.
_MIN_VARIANCE = 1e-12


def load_frame(path: Path, cfa_pattern: str | None, saturation: float = 0.95,
               white_level: float | None = None, demosaic: str = "bilinear",
               source: str | Path | None = None,
               field: str = "") -> tuple[np.ndarray, np.ndarray]:
    """One frame as ``(H, W, 3)`` linear values (data numbers) and its saturation mask
    (:func:`_read_frame` without the Bayer pattern it used)."""
    rgb, saturated, _ = _read_frame(path, cfa_pattern, saturation, white_level, demosaic, source,
                                    field)
    return rgb, saturated


def _read_frame(path: Path, cfa_pattern: str | None, saturation: float = 0.95,
                white_level: float | None = None, demosaic: str = "bilinear",
                source: str | Path | None = None,
                field: str = "") -> tuple[np.ndarray, np.ndarray, str | None]:
    """One frame as ``(H, W, 3)`` linear values (data numbers), its saturation mask and the
    Bayer pattern it was demosaiced with (``None`` for an EXR frame).

    Raw mosaics are demosaiced (CFA pattern from the file, else ``cfa_pattern``), with the black
    level subtracted. ``demosaic="bilinear"``: a demosaiced pixel is saturated when any mosaic
    site within its 3x3 neighbourhood (the bilinear kernels' support) of the same colour is at
    or above ``saturation`` times the white level (``white_level`` if given, else the file's):
    interpolation would otherwise hide a clipped neighbour (at the border, reflected bilinear
    gives half a clipped value). ``demosaic="superpixel"``: ``(H/2, W/2, 3)``, a superpixel's
    colour is saturated when any of its cell's sites of that colour is (for green, either of
    two). EXR files are taken as already linear RGB, never saturated (bilinear only).
    ``source`` and ``field`` (the build file and e.g. ``views[0].frames[2]``) name the input in
    errors about the image's size or kind.
    """
    if demosaic not in DEMOSAIC_METHODS:
        raise InputError(source, "demosaic", f"expected one of {', '.join(DEMOSAIC_METHODS)}, "
                                             f"got {demosaic!r}")
    if path.suffix.lower() == ".exr":
        if demosaic == "superpixel":
            raise InputError(source or path, field, f"{path.name} is a linear RGB EXR, not a "
                                                    "mosaic: demosaic \"superpixel\" needs raw "
                                                    "mosaics (use \"bilinear\" for EXR frames)")
        rgb = read_image(path).astype(np.float64)
        return rgb, np.zeros(rgb.shape, bool), None
    frame = read_raw(path)
    pattern = frame.cfa_pattern or cfa_pattern
    if pattern is None:
        raise InputError(path, "cfa_pattern", "the file does not state its Bayer pattern; give "
                                              "cfa_pattern (RGGB, BGGR, GRBG or GBRG)")
    white = frame.white_level if white_level is None else float(white_level)
    clipped = frame.mosaic >= saturation * white
    if demosaic == "superpixel":
        h, w = frame.mosaic.shape
        if h % 2 or w % 2:
            raise InputError(source or path, field if source else "size",
                             f"{path.name} is {w}x{h} pixels: demosaic \"superpixel\" needs an "
                             "even width and height (crop one row or column of every frame, "
                             "dark and mask, or use \"bilinear\")")
        rgb = demosaic_superpixel(frame.mosaic - frame.black_level, pattern).astype(np.float64)
        return rgb, superpixel_any(clipped, pattern), pattern
    sites = cfa_masks(frame.mosaic.shape, pattern)
    near_clipped = np.stack([cv2.dilate((clipped & sites[..., c]).astype(np.uint8),
                                        np.ones((3, 3), np.uint8)).astype(bool)
                             for c in range(3)], axis=-1)
    rgb = demosaic_bilinear(frame.mosaic - frame.black_level, pattern).astype(np.float64)
    return rgb, near_clipped, pattern


def _view_hdr(entry: dict[str, Any], folder: Path, cfa: str | None, source: Path,
              field: str, white_level: float | None = None,
              demosaic: str = "bilinear") -> tuple[MergedHDR, str | None]:
    """A view's frames merged, and the Bayer pattern of its raw frames (``None``: all EXR)."""
    frames = entry["frames"]
    if not isinstance(frames, list) or not frames:
        raise InputError(source, f"{field}.frames", "expected a non-empty list of files")
    exposures = entry.get("exposures_s", [1.0] * len(frames) if len(frames) == 1 else None)
    if not isinstance(exposures, list) or len(exposures) != len(frames):
        raise InputError(source, f"{field}.exposures_s", f"expected {len(frames)} exposure times "
                                                         "(seconds), one per frame")
    read = [_read_frame(folder / f, cfa, white_level=white_level, demosaic=demosaic,
                        source=source, field=f"{field}.frames[{k}]")
            for k, f in enumerate(frames)]
    loaded = [(img, saturated) for img, saturated, _ in read]
    pattern = next((p for _, _, p in read if p is not None), None)
    shapes = {img.shape for img, _ in loaded}
    if len(shapes) > 1:
        raise InputError(source, f"{field}.frames", f"mixed image sizes {sorted(shapes)}")
    darks = None
    if entry.get("darks") is not None:
        if not isinstance(entry["darks"], list) or len(entry["darks"]) != len(frames):
            raise InputError(source, f"{field}.darks", f"expected {len(frames)} dark frames, one "
                                                       "per frame (the same file may repeat)")
        darks = [load_frame(folder / f, cfa, demosaic=demosaic, source=source,
                            field=f"{field}.darks[{k}]")[0]
                 for k, f in enumerate(entry["darks"])]
        for f, d in zip(entry["darks"], darks):
            if d.shape != loaded[0][0].shape:
                raise InputError(folder / f, "", f"dark frame is {d.shape[1]}x{d.shape[0]}, "
                                                 f"frames {loaded[0][0].shape[1]}x"
                                                 f"{loaded[0][0].shape[0]}: mixed image sizes")
    return merge_brackets([img for img, _ in loaded], exposures, np.inf, darks,
                          saturated=[sat for _, sat in loaded], source=f"{source}: {field}"), pattern


def build_capture(build_file: str | Path, out: str | Path,
                  progress: Callable[[int], None] | None = None,
                  demosaic: str | None = None) -> tuple[Capture, dict[str, MergedHDR]]:
    """Build a capture folder from a build file (format in the module docstring).

    ``demosaic`` (``"bilinear"`` or ``"superpixel"``) overrides the build file's ``demosaic``
    (default ``"bilinear"``).

    Returns
    -------
    Capture
        The written capture, as :func:`abs.io.capture.load_capture` reads it.
    dict of str to MergedHDR
        The merge of each view (weight maps for the report).
    """
    source = Path(build_file)
    spec = read_json(source, what="build file")
    folder = source.parent
    if "cameras" not in spec or "views" not in spec:
        raise InputError(source, "", "expected an object with 'cameras' and 'views'")
    cameras = read_camera_file(folder / spec["cameras"])
    cfa = spec.get("cfa_pattern")
    white_level = spec.get("white_level")
    if white_level is not None and (isinstance(white_level, bool)
                                    or not isinstance(white_level, (int, float))
                                    or not white_level > 0):
        raise InputError(source, "white_level", f"expected a positive number of data numbers, "
                                                f"got {white_level!r}")
    if demosaic is None:
        demosaic = spec.get("demosaic", DEMOSAIC_METHODS[0])
        demosaic_source, demosaic_field = source, "demosaic"
    else:
        demosaic_source, demosaic_field = None, "demosaic"
    if demosaic not in DEMOSAIC_METHODS:
        raise InputError(demosaic_source, demosaic_field, f"expected one of "
                                                          f"{', '.join(DEMOSAIC_METHODS)}, got "
                                                          f"{demosaic!r}")
    try:
        lens_blur = lens_blur_px(spec.get("lens_blur_px", 0.0))
    except ValueError as exc:
        raise InputError(source, "lens_blur_px", str(exc)) from None
    superpixel = demosaic == "superpixel"
    views, images, masks, merges, blurs, blur_keys, processing = [], {}, {}, {}, {}, [], {}
    noise = {}
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
        merged, pattern = _view_hdr(entry, folder, cfa, source, field, white_level, demosaic)
        factor = 2 if superpixel else 1
        h_img, w_img = (factor * n for n in merged.radiance.shape[:2])
        if (h_img, w_img) != (cam.height, cam.width):
            raise InputError(source, f"{field}.frames", f"images are {w_img}x{h_img}, camera "
                                                        f"{entry['camera']} is {cam.width}x"
                                                        f"{cam.height}: mixed image sizes")
        # The camera of the merged image: the calibrated one, or at superpixel resolution.
        cam_img = superpixel_camera(cam) if superpixel else cam
        K_new = pinhole_K(cam_img)
        # Linear EXR frames are RGB already: only undistortion blurs them.
        raw = any(Path(f).suffix.lower() != ".exr" for f in entry["frames"])
        key = (entry["camera"], raw)
        if key not in blurs:
            try:
                blurs[key] = processing_blur(cam, K_new, demosaic if raw else None)
            except ValueError as exc:
                raise InputError(source, f"{field}.camera", f"{entry['camera']}: {exc}") from None
        blur_keys.append(key)
        processing[entry["name"]] = SensorProcessing(
            cam.width, cam.height, cam.K, cam.distortion, demosaic if raw else None, pattern,
            lens_blur)
        images[entry["name"]] = undistort_image(merged.radiance, cam_img, K_new)
        if raw:
            # The merge's shot and read noise, resampled as the image is (a local mean of the
            # variances its pixels are made from: what weighs pixels against each other; the
            # spreading of each site's noise to its neighbours is the footprint's correlation).
            # Pixels that sample outside the frame (none at the build's zoom) weigh least.
            variance = merged.variance
            if superpixel:  # a superpixel's green is the mean of its cell's two green sites
                variance = variance * np.array([1.0, 0.5, 1.0], np.float32)
            variance = undistort_image(variance, cam_img, K_new).astype(np.float64)
            variance = np.where(variance > 0, variance, max(float(variance.max()), _MIN_VARIANCE))
            noise[entry["name"]] = np.sqrt(np.maximum(variance, _MIN_VARIANCE))
        if entry.get("mask") is not None:
            mask = read_mask(folder / entry["mask"], (cam.height, cam.width))
            if superpixel:
                mask = superpixel_mask(mask)
            masks[entry["name"]] = undistort_mask(mask, cam_img, K_new)
        views.append({"name": entry["name"], "K": K_new, "R": cam.R, "t": cam.t,
                      "holdout": bool(entry.get("holdout", False))})
        merges[entry["name"]] = merged
        if progress is not None:
            progress(1)
    # One blur per capture: the views' variances averaged (variance is what sets the blur).
    blur_px = (np.sqrt(np.mean([np.square(blurs[k]) for k in blur_keys], axis=0)) if blur_keys
               else np.zeros(3))
    return save_capture(out, views, images, masks or None, blur_px=blur_px,
                        processing=processing, noise=noise), merges
