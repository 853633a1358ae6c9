"""Capture folders: photographs plus their calibrated OpenCV cameras (a public contract).

A capture folder holds ``cameras.json`` next to the photographs::

    {"views": [{"name": "v0", "image": "v0.exr",
                "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
                "R": [[...], [...], [...]], "t": [tx, ty, tz],
                "holdout": false, "mask": "v0_mask.png"}],
     "blur_px": [0.8, 0.65, 0.8],
     "processing": {"v0": {"width": 1280, "height": 1024, "K": [[...], [...], [...]],
                           "distortion": [k1, k2, p1, p2, k3], "demosaic": "bilinear",
                           "cfa_pattern": "RGGB"}},
     "noise": {"v0": "noise/v0.exr"}}

- ``name``: unique, usable as a file name (letters, digits, ``_``, ``-``, ``.``; not starting
  with ``.`` or ``-``; at most 128 characters).
- ``image``: photograph path relative to the folder (or absolute); EXR, HDR, PNG or JPEG
  (see :mod:`abs.io.images`).
- ``K`` (pixels), ``R``, ``t`` (metres): OpenCV convention of docs/conventions.md,
  ``x_cam = R @ X_world + t``. ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with fx, fy > 0.
- ``holdout`` (optional, default false): the view is kept out of fitting, for validation.
- ``mask`` (optional): image of the photograph's size whose nonzero pixels are compared.
- ``blur_px`` (optional, top level, default ``[0, 0, 0]``): per R, G, B, the standard deviation
  in pixels of a Gaussian blur that the photographs' processing added beyond each pixel's own
  footprint, in every view (``abs capture build`` writes its demosaicing and undistortion's,
  docs/acquisition.md). Renderings are blurred alike before they are compared. Readers that
  ignore it (unknown top-level keys are ignored) compare unblurred renderings, as before.
- ``processing`` (optional, top level): per view name, how ``abs capture build`` made the
  photograph from its camera's sensor: the sensor's size (pixels), its calibrated matrix ``K``
  and OpenCV ``distortion`` coefficients (4, 5, 8, 12 or 14), the ``demosaic`` method
  (``"bilinear"``, ``"superpixel"``, or ``null`` for frames that were RGB already) and the
  ``cfa_pattern`` (``RGGB``, ``BGGR``, ``GRBG``, ``GBRG``; ``null`` without demosaicing), and
  optionally ``lens_blur_px``, the standard deviation in sensor pixels of the lens's Gaussian
  point-spread function (the build cannot know it; default 0). With
  it, renderings of the view average exactly the sensor sites each built pixel averages
  (:mod:`abs.acquisition.footprint`) instead of being blurred by ``blur_px``. Readers that ignore
  it use ``blur_px``.
- ``noise`` (optional, top level): per view name, an image file (EXR, the photograph's size, 3
  channels) of the standard deviation of the photograph's noise per pixel and channel, in the
  photograph's units **up to one factor common to the capture**: fits weigh each residual by
  it (the noisier a pixel, the less it counts: docs/fitting.md, Pixel weights), and estimate the
  noise's level from the residuals as without it. ``abs capture build`` writes the shot and
  read noise of its merged brackets (docs/acquisition.md): in a photograph merged from brackets
  the noise grows with the light, and a few bright glints would otherwise outweigh the rest of
  the image. Values must be finite and positive. Readers that ignore it weigh all pixels alike,
  as before.

Keys of a view starting with ``_`` are comments and ignored; other unknown keys are errors, so a
typo such as ``holdOut`` cannot silently change meaning. Unknown top-level keys are ignored.
Every error is a :class:`abs.errors.CaptureError` naming ``cameras.json`` and the field, e.g.
``captures/mug/cameras.json: views[2].R: not orthonormal ...``.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from abs.errors import CaptureError, InputError, read_json
from abs.io.images import (IMAGE_EXTENSIONS, image_size, read_image, read_mask, write_exr,
                           write_mask)

__all__ = ["CAMERAS_FILE", "View", "Capture", "SensorProcessing", "load_capture", "save_capture",
           "lens_blur_px"]

CAMERAS_FILE = "cameras.json"
ROTATION_TOL = 1e-5  # max |R^T R - I| and |det R - 1| accepted as a rotation
_NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")
_VIEW_KEYS = {"name", "image", "K", "R", "t", "holdout", "mask"}
_REQUIRED_KEYS = ("name", "image", "K", "R", "t")
_PROCESSING_KEYS = {"width", "height", "K", "distortion", "demosaic", "cfa_pattern", "lens_blur_px"}
# The demosaicing methods of abs.acquisition.demosaic (None: frames that were RGB already) and
# Bayer patterns, repeated here because file formats sit below the acquisition code.
_DEMOSAIC = ("bilinear", "superpixel", None)
_CFA = ("RGGB", "BGGR", "GRBG", "GBRG")


# --------------------------------------------------------------------------------------------
# Field validators: each returns the clean value or raises CaptureError(source, field, ...).


def _matrix(value: Any, shape: tuple[int, ...], source: Path | None, field: str) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape``."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.shape != shape or isinstance(value, (str, bytes)):
        what = (f"{shape[0]} numbers" if len(shape) == 1
                else f"a {shape[0]}x{shape[1]} array of numbers")
        raise CaptureError(source, field, f"expected {what}, got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise CaptureError(source, field, f"values must be finite, got {arr.tolist()}")
    return arr


def _check_name(value: Any, source: Path | None, field: str) -> str:
    if not isinstance(value, str) or not _NAME_RE.fullmatch(value) or value.endswith("."):
        raise CaptureError(source, field, f"{value!r} is not usable as a file name (letters, "
                                          "digits, '_', '-', '.'; not starting with '.' or '-')")
    return value


def _check_K(value: Any, source: Path | None, field: str) -> np.ndarray:
    K = _matrix(value, (3, 3), source, field)
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CaptureError(source, field, f"focal lengths fx = K[0][0] and fy = K[1][1] must be "
                                          f"> 0 pixels, got fx = {K[0, 0]}, fy = {K[1, 1]}"
                                          f"{' (K is singular)' if K[0, 0] * K[1, 1] == 0 else ''}")
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise CaptureError(source, field, "expected the form [[fx, s, cx], [0, fy, cy], "
                                          f"[0, 0, 1]], got {K.tolist()}")
    # Redundant with the form above (det = fx * fy), kept so that no singular K ever passes.
    if abs(np.linalg.det(K)) < 1e-12 or np.linalg.cond(K) > 1e12:
        raise CaptureError(source, field, f"K is singular (not invertible): {K.tolist()}")
    return K


def _check_R(value: Any, source: Path | None, field: str) -> np.ndarray:
    R = _matrix(value, (3, 3), source, field)
    off = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if off > ROTATION_TOL:
        raise CaptureError(source, field, f"not orthonormal: max |R^T R - I| = {off:.3g} > "
                                          f"{ROTATION_TOL:g}")
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > ROTATION_TOL:
        raise CaptureError(source, field, f"det(R) = {det:.6g}, expected +1 (a rotation, not a "
                                          "reflection)")
    return R


def _check_t(value: Any, source: Path | None, field: str) -> np.ndarray:
    return _matrix(value, (3,), source, field)


def _check_holdout(value: Any, source: Path | None, field: str) -> bool:
    if not isinstance(value, bool):
        raise CaptureError(source, field, f"expected true or false, got {value!r}")
    return value


def _check_blur(value: Any, source: Path | None, field: str) -> tuple[float, float, float]:
    # Demosaicing and resampling blur by about a pixel: beyond 10 the value is a mistake (units?).
    blur = _matrix(value, (3,), source, field)
    if np.any(blur < 0) or np.any(blur > 10):
        raise CaptureError(source, field, f"expected 3 standard deviations in [0, 10] pixels "
                                          f"(R, G, B), got {blur.tolist()}")
    return tuple(float(b) for b in blur)


def _check_keys(value: Any, allowed: set[str], required, source: Path | None, field: str) -> None:
    """``value`` is an object whose keys are ``allowed`` (or comments, ``_...``) and include
    every ``required`` one."""
    if not isinstance(value, Mapping):
        raise CaptureError(source, field, f"expected an object, got {type(value).__name__}")
    unknown = sorted(k for k in value if k not in allowed and not k.startswith("_"))
    if unknown:
        raise CaptureError(source, f"{field}.{unknown[0]}", f"unknown key; allowed keys are "
                                                            f"{', '.join(sorted(allowed))}")
    for key in required:
        if key not in value:
            raise CaptureError(source, f"{field}.{key}", "missing")


def _check_processing(value: Any, source: Path | None, field: str) -> "SensorProcessing":
    _check_keys(value, _PROCESSING_KEYS, ("width", "height", "K", "distortion", "demosaic"),
                source, field)
    size = []
    for key in ("width", "height"):
        n = value[key]
        if isinstance(n, bool) or not isinstance(n, int) or n <= 0:
            raise CaptureError(source, f"{field}.{key}", f"expected a positive whole number of "
                                                         f"sensor pixels, got {n!r}")
        size.append(n)
    K = _check_K(value["K"], source, f"{field}.K")
    distortion = value["distortion"]
    n = len(distortion) if isinstance(distortion, (list, tuple)) else -1
    if n not in (4, 5, 8, 12, 14):
        raise CaptureError(source, f"{field}.distortion", f"expected 4, 5, 8, 12 or 14 OpenCV "
                                                          f"coefficients, got {distortion!r}")
    distortion = _matrix(distortion, (n,), source, f"{field}.distortion")
    demosaic = value["demosaic"]
    if demosaic not in _DEMOSAIC:
        raise CaptureError(source, f"{field}.demosaic", f"expected \"bilinear\", \"superpixel\" "
                                                        f"or null, got {demosaic!r}")
    pattern = value.get("cfa_pattern")
    if demosaic is not None and pattern not in _CFA:
        raise CaptureError(source, f"{field}.cfa_pattern", f"expected one of {', '.join(_CFA)} "
                                                           f"(demosaic {demosaic}), got {pattern!r}")
    try:
        blur = lens_blur_px(value.get("lens_blur_px", 0.0))
    except ValueError as exc:
        raise CaptureError(source, f"{field}.lens_blur_px", str(exc)) from None
    return SensorProcessing(size[0], size[1], _read_only(K), _read_only(distortion), demosaic,
                            None if demosaic is None else pattern, blur)


def _check_noise(sd: Any, shape: tuple[int, ...], source: Path | None, field: str) -> np.ndarray:
    """A noise image (standard deviations) as float64, checked: the photograph's ``shape``,
    every value finite and positive."""
    sd = np.asarray(sd, np.float64)
    if sd.shape != tuple(shape):
        raise CaptureError(source, field, f"noise image of shape {sd.shape} differs from the "
                                          f"photograph's {tuple(shape)}")
    bad = int(np.count_nonzero(~(np.isfinite(sd) & (sd > 0))))
    if bad:
        raise CaptureError(source, field, f"{bad} values are not finite and positive (a standard "
                                          "deviation per pixel and channel)")
    return sd


def lens_blur_px(value: Any) -> float:
    """A lens blur's standard deviation (sensor pixels) as given in a file, checked: a number in
    [0, 10]. The one rule for the capture's ``processing`` and the build file that writes it;
    ``ValueError`` otherwise (callers name their file and field)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 10:
        raise ValueError(f"expected a standard deviation in [0, 10] sensor pixels, got {value!r}")
    return float(value)


def _read_only(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, dtype=np.float64)
    arr.setflags(write=False)
    return arr


# --------------------------------------------------------------------------------------------
# Data model


@dataclass(frozen=True, eq=False)
class SensorProcessing:
    """How a capture build made a view's photograph from its camera's sensor (``cameras.json``'s
    optional top-level ``processing``): enough to rebuild, with the build's own functions, which
    sensor sites each built pixel averages (:func:`abs.acquisition.footprint.processing_footprint`).

    Attributes
    ----------
    width, height : int
        The sensor's size, pixels.
    K : np.ndarray
        (3, 3) the calibrated (distorted) camera's matrix at the sensor's resolution, pixels.
    distortion : np.ndarray
        OpenCV distortion coefficients ``k1, k2, p1, p2[, k3, ...]``.
    demosaic : str or None
        ``"bilinear"`` or ``"superpixel"``; ``None`` for frames that were RGB already (linear EXR
        brackets: undistortion only).
    cfa_pattern : str or None
        The Bayer pattern of the raw frames (``None`` without demosaicing).
    lens_blur_px : float
        Standard deviation of a Gaussian point-spread function of the lens (and any optical
        low-pass filter) on the sensor, sensor pixels: what reaches a site is the light blurred
        by it. The build cannot know it (0 unless given: ``lens_blur_px`` in the file).
    """

    width: int
    height: int
    K: np.ndarray
    distortion: np.ndarray
    demosaic: str | None
    cfa_pattern: str | None = None
    lens_blur_px: float = 0.0

    def key(self) -> tuple:
        """The values as a hashable tuple (equal processings have equal keys)."""
        return (self.width, self.height, tuple(np.asarray(self.K, float).ravel()),
                tuple(np.asarray(self.distortion, float).ravel()), self.demosaic, self.cfa_pattern,
                float(self.lens_blur_px))

    def to_json(self) -> dict[str, Any]:
        out = {"width": int(self.width), "height": int(self.height),
               "K": np.asarray(self.K, float).tolist(),
               "distortion": np.asarray(self.distortion, float).tolist(),
               "demosaic": self.demosaic, "cfa_pattern": self.cfa_pattern}
        if self.lens_blur_px:
            out["lens_blur_px"] = float(self.lens_blur_px)
        return out


@dataclass(frozen=True, eq=False)
class View:
    """One calibrated photograph.

    Attributes
    ----------
    name : str
        Unique view name, usable as a file name.
    image : Path
        Absolute path of the photograph.
    K : np.ndarray
        (3, 3) intrinsics, pixels, float64, read-only.
    R : np.ndarray
        (3, 3) world-to-camera rotation, read-only.
    t : np.ndarray
        (3,) world-to-camera translation, metres, read-only.
    width, height : int
        Photograph size, pixels.
    holdout : bool
        Kept out of fitting (validation view).
    mask : Path or None
        Absolute path of the comparison mask (nonzero = compared), or ``None`` for all pixels.
    blur_px : tuple of 3 float
        The photograph's processing blur per R, G, B (Gaussian standard deviation, pixels; the
        capture file's top-level ``blur_px``).
    processing : SensorProcessing or None
        How a capture build made the photograph from the sensor (``processing[name]``), or
        ``None``.
    noise : Path or None
        Absolute path of the photograph's noise image (``noise[name]``: standard deviation per
        pixel and channel, up to a factor common to the capture), or ``None``.
    """

    name: str
    image: Path
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    holdout: bool = False
    mask: Path | None = None
    blur_px: tuple[float, float, float] = (0.0, 0.0, 0.0)
    processing: SensorProcessing | None = None
    noise: Path | None = None

    def __post_init__(self) -> None:
        where = f"View({self.name!r})"
        _check_name(self.name, None, f"{where}.name")
        object.__setattr__(self, "blur_px", _check_blur(self.blur_px, None, f"{where}.blur_px"))
        object.__setattr__(self, "image", Path(self.image))
        object.__setattr__(self, "K", _read_only(_check_K(self.K, None, f"{where}.K")))
        object.__setattr__(self, "R", _read_only(_check_R(self.R, None, f"{where}.R")))
        object.__setattr__(self, "t", _read_only(_check_t(self.t, None, f"{where}.t")))
        if self.mask is not None:
            object.__setattr__(self, "mask", Path(self.mask))
        if self.noise is not None:
            object.__setattr__(self, "noise", Path(self.noise))
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise CaptureError(None, f"{where}.size", f"invalid size {self.width}x{self.height}")

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, ``-R^T t``, metres."""
        return -self.R.T @ self.t

    def read_image(self) -> np.ndarray:
        """The photograph as ``(height, width, 3)`` linear RGB ``float32``."""
        return read_image(self.image)

    def read_mask(self) -> np.ndarray:
        """The ``(height, width)`` boolean mask, all ``True`` when the view has none."""
        if self.mask is None:
            return np.ones((self.height, self.width), dtype=bool)
        return read_mask(self.mask, (self.height, self.width))

    def read_noise(self) -> np.ndarray | None:
        """The photograph's noise standard deviation as ``(height, width, 3)`` ``float64`` (up
        to a factor common to the capture), or ``None`` when the view has none.

        Raises
        ------
        CaptureError
            Naming the file, when its size differs from the photograph's or a value is not
            finite and positive.
        """
        if self.noise is None:
            return None
        return _check_noise(read_image(self.noise), (self.height, self.width, 3), self.noise,
                            f"noise.{self.name}")


@dataclass(frozen=True, eq=False)
class Capture:
    """A loaded capture folder.

    Attributes
    ----------
    folder : Path
        Absolute path of the capture folder.
    views : tuple of View
        All views, in file order.
    """

    folder: Path
    views: tuple[View, ...]

    @property
    def source(self) -> Path:
        """Path of the ``cameras.json`` file."""
        return self.folder / CAMERAS_FILE

    @property
    def names(self) -> tuple[str, ...]:
        """View names, in file order."""
        return tuple(v.name for v in self.views)

    @property
    def train_views(self) -> tuple[View, ...]:
        """Views used for fitting (``holdout`` false)."""
        return tuple(v for v in self.views if not v.holdout)

    @property
    def holdout_views(self) -> tuple[View, ...]:
        """Views kept out of fitting (``holdout`` true)."""
        return tuple(v for v in self.views if v.holdout)

    def view(self, name: str) -> View:
        """The view called ``name``; ``KeyError`` listing the known names otherwise."""
        for v in self.views:
            if v.name == name:
                return v
        raise KeyError(f"{self.source}: no view named {name!r}; views are "
                       f"{', '.join(self.names)}")


# --------------------------------------------------------------------------------------------
# Loading


def _resolve(folder: Path, value: Any, source: Path, field: str) -> Path:
    if not isinstance(value, str) or not value:
        raise CaptureError(source, field, f"expected a file path string, got {value!r}")
    path = Path(value)
    return path if path.is_absolute() else (folder / path)


def _image_size(path: Path, source: Path, field: str,
                extensions: tuple[str, ...]) -> tuple[int, int]:
    """Header size of a referenced image; file problems become errors on ``field``."""
    if not path.is_file():
        raise CaptureError(source, field, f"file not found: {path}")
    if path.suffix.lower() not in extensions:
        raise CaptureError(source, field, f"unsupported image format {path.suffix!r}; expected "
                                          f"one of {', '.join(extensions)}")
    try:
        return image_size(path)
    except InputError as exc:
        raise CaptureError(source, field, f"{path}: {exc.message}") from exc


def _parse_view(entry: Any, index: int, folder: Path, source: Path,
                blur_px: tuple[float, float, float]) -> View:
    field = f"views[{index}]"
    _check_keys(entry, _VIEW_KEYS, _REQUIRED_KEYS, source, field)
    name = _check_name(entry["name"], source, f"{field}.name")
    K = _check_K(entry["K"], source, f"{field}.K")
    R = _check_R(entry["R"], source, f"{field}.R")
    t = _check_t(entry["t"], source, f"{field}.t")
    holdout = _check_holdout(entry.get("holdout", False), source, f"{field}.holdout")
    image = _resolve(folder, entry["image"], source, f"{field}.image")
    width, height = _image_size(image, source, f"{field}.image", IMAGE_EXTENSIONS)
    mask = None
    if entry.get("mask") is not None:
        mask = _resolve(folder, entry["mask"], source, f"{field}.mask")
        mask_size = _image_size(mask, source, f"{field}.mask",
                                (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".exr"))
        if mask_size != (width, height):
            raise CaptureError(source, f"{field}.mask", f"mask is {mask_size[0]}x{mask_size[1]} "
                                                        f"pixels, photograph {width}x{height}")
    return View(name=name, image=image.absolute(), K=K, R=R, t=t, width=width, height=height,
                holdout=holdout, mask=None if mask is None else mask.absolute(), blur_px=blur_px)


def load_capture(folder: str | Path) -> Capture:
    """Load and validate a capture folder.

    Parameters
    ----------
    folder : str or Path
        The capture folder, or its ``cameras.json`` file directly.

    Returns
    -------
    Capture
        Views in file order with absolute paths and header-read image sizes (pixels are not
        decoded here; use :meth:`View.read_image`).

    Raises
    ------
    CaptureError
        Naming ``cameras.json`` and the offending field (``views[i].K`` etc.) when the file is
        missing, not JSON, or any view is invalid: non-finite or wrongly shaped numbers, fx or
        fy <= 0, ``K[2] != [0, 0, 1]``, singular K, R not orthonormal or det(R) != +1
        (tolerance 1e-5), duplicate or unusable names, missing image or mask files, a mask whose
        size differs from its photograph.
    """
    path = Path(folder)
    if path.suffix.lower() == ".json" and not path.is_dir():
        source, folder = path, path.parent
    else:
        source, folder = path / CAMERAS_FILE, path
    folder = folder.absolute()
    data = read_json(source, what="capture file", hint=f"a capture folder needs {CAMERAS_FILE}, "
                     "a JSON object with a 'views' list", error=CaptureError)
    views = data.get("views")
    if not isinstance(views, list) or not views:
        raise CaptureError(source, "views", f"expected a non-empty list of views, got {views!r}")
    blur_px = _check_blur(data.get("blur_px", [0.0, 0.0, 0.0]), source, "blur_px")
    parsed: list[View] = []
    seen: dict[str, int] = {}
    for i, entry in enumerate(views):
        view = _parse_view(entry, i, folder, source, blur_px)
        if view.name in seen:
            raise CaptureError(source, f"views[{i}].name", f"duplicate name {view.name!r} "
                                                           f"(also views[{seen[view.name]}])")
        seen[view.name] = i
        parsed.append(view)
    processing = data.get("processing")
    if processing is not None:
        if not isinstance(processing, dict):
            raise CaptureError(source, "processing", f"expected an object of view names, got "
                                                     f"{type(processing).__name__}")
        for name in processing:
            if name not in seen:
                raise CaptureError(source, f"processing.{name}", "no view has this name")
        parsed = [view if view.name not in processing else
                  replace(view, processing=_check_processing(processing[view.name], source,
                                                             f"processing.{view.name}"))
                  for view in parsed]
        for view in parsed:
            p = view.processing
            factor = 2 if p is not None and p.demosaic == "superpixel" else 1
            if p is not None and (view.width * factor, view.height * factor) != (p.width, p.height):
                raise CaptureError(source, f"processing.{view.name}",
                                   f"a {view.width}x{view.height} photograph cannot come from the "
                                   f"{p.width}x{p.height} sensor by demosaic {p.demosaic} (was the "
                                   "photograph resized after the build?)")
    noise = data.get("noise")
    if noise is not None:
        if not isinstance(noise, dict):
            raise CaptureError(source, "noise", f"expected an object of view names, got "
                                                f"{type(noise).__name__}")
        sizes = {view.name: (view.width, view.height) for view in parsed}
        paths = {}
        for name, value in noise.items():
            if name not in seen:
                raise CaptureError(source, f"noise.{name}", "no view has this name")
            path = _resolve(folder, value, source, f"noise.{name}")
            size = _image_size(path, source, f"noise.{name}", (".exr",))
            if size != sizes[name]:
                raise CaptureError(source, f"noise.{name}", f"noise image is {size[0]}x{size[1]} "
                                                           f"pixels, photograph "
                                                           f"{sizes[name][0]}x{sizes[name][1]}")
            paths[name] = path.absolute()
        parsed = [replace(view, noise=paths.get(view.name)) for view in parsed]
    return Capture(folder=folder, views=tuple(parsed))


# --------------------------------------------------------------------------------------------
# Saving


def _json_map(key: str, entries: Mapping[str, Any]) -> str:
    """A top-level object of ``cameras.json`` keyed by view name, one view per line, as it
    follows the ``views`` list."""
    lines = ",\n".join(f"    {json.dumps(name)}: {json.dumps(value)}"
                        for name, value in entries.items())
    return f',\n  "{key}": {{\n' + lines + "\n  }"


def _json_view(view: View, folder: Path) -> str:
    """One view as compact JSON, one key per line and matrices row by row."""
    def rel(path: Path) -> str:
        try:
            return path.relative_to(folder).as_posix()
        except ValueError:
            return str(path)

    def numbers(values: np.ndarray) -> str:
        return json.dumps([float(x) + 0.0 for x in values])  # + 0.0 turns -0.0 into 0.0

    def rows(matrix: np.ndarray) -> str:
        return "[" + ", ".join(numbers(r) for r in matrix) + "]"

    lines = [f'"name": {json.dumps(view.name)}',
             f'"image": {json.dumps(rel(view.image))}',
             f'"K": {rows(view.K)}',
             f'"R": {rows(view.R)}',
             f'"t": {numbers(view.t)}',
             f'"holdout": {json.dumps(view.holdout)}']
    if view.mask is not None:
        lines.append(f'"mask": {json.dumps(rel(view.mask))}')
    return "    {\n      " + ",\n      ".join(lines) + "\n    }"


def save_capture(folder: str | Path, views: Sequence[View | Mapping[str, Any]],
                 images: Mapping[str, np.ndarray] | None = None,
                 masks: Mapping[str, np.ndarray] | None = None,
                 blur_px: Sequence[float] | None = None,
                 processing: Mapping[str, SensorProcessing] | None = None,
                 noise: Mapping[str, np.ndarray] | None = None) -> Capture:
    """Write a capture folder: ``<name>.exr`` photographs, ``<name>_mask.png`` masks,
    ``noise/<name>.exr`` noise images (a folder of their own: no view's name can make a noise
    image's file another view's photograph) and ``cameras.json`` (written last, atomically),
    then load it back.

    Parameters
    ----------
    folder : str or Path
        Destination folder, created if needed; existing files of the same names are replaced.
    views : sequence of View or mapping
        Cameras in order. A mapping has keys ``name``, ``K``, ``R``, ``t`` and optionally
        ``holdout`` (arrays or nested lists). File names are always chosen by this function.
    images : mapping of str to np.ndarray, optional
        Photograph per view name, ``(height, width, 3)`` linear RGB. A view missing here must be
        a :class:`View`, whose existing photograph is copied (re-encoded as EXR).
    masks : mapping of str to np.ndarray, optional
        ``(height, width)`` masks (nonzero = compared) per view name. A :class:`View` missing
        here keeps its existing mask, if any.
    blur_px : sequence of 3 float, optional
        The photographs' processing blur per R, G, B (pixels; top-level ``blur_px``). Default:
        that of the :class:`View` items (which must agree), zeros when all are mappings.
    processing : mapping of str to SensorProcessing, optional
        How the photographs were made from the sensor, per view name (top-level
        ``processing``). Default: that of the :class:`View` items that have one.
    noise : mapping of str to np.ndarray, optional
        The photographs' noise standard deviation, ``(height, width, 3)``, per view name
        (top-level ``noise``; up to a factor common to the capture). A :class:`View` missing
        here keeps its existing noise image, if any, unless ``images`` replaces its photograph
        (the old noise image would not describe the new one).

    Returns
    -------
    Capture
        The capture as :func:`load_capture` reads it back.

    Raises
    ------
    CaptureError
        For invalid cameras, names, images or masks (source ``None``: the values came from
        Python; fields as in ``cameras.json``, e.g. ``views[1].R``).
    """
    folder = Path(folder).absolute()
    images = dict(images or {})
    masks = dict(masks or {})
    noise = dict(noise or {})
    if not views:
        raise CaptureError(None, "views", "expected at least one view")
    if blur_px is None:
        blurs = {v.blur_px for v in views if isinstance(v, View)}
        if len(blurs) > 1:
            raise CaptureError(None, "blur_px", f"the views' blurs differ ({sorted(blurs)}); a "
                                                "capture has one: give blur_px")
        blur_px = blurs.pop() if blurs else (0.0, 0.0, 0.0)
    blur_px = _check_blur(blur_px, None, "blur_px")
    if processing is None:
        processing = {v.name: v.processing for v in views
                      if isinstance(v, View) and v.processing is not None}
    processing = {name: _check_processing(p.to_json(), None, f"processing.{name}")
                  for name, p in processing.items()}

    # Validate everything before writing anything.
    prepared: list[tuple[dict[str, Any], np.ndarray, np.ndarray | None]] = []
    seen: set[str] = set()
    for i, item in enumerate(views):
        field = f"views[{i}]"
        if isinstance(item, View):
            spec = {"name": item.name, "K": item.K, "R": item.R, "t": item.t,
                    "holdout": item.holdout}
        elif isinstance(item, Mapping):
            spec = dict(item)
            unknown = sorted(set(spec) - {"name", "K", "R", "t", "holdout"})
            if unknown:
                raise CaptureError(None, f"{field}.{unknown[0]}", "unknown key; expected name, K, "
                                                                  "R, t, holdout")
        else:
            raise CaptureError(None, field, f"expected a View or a mapping, got "
                                            f"{type(item).__name__}")
        for key in ("name", "K", "R", "t"):
            if key not in spec:
                raise CaptureError(None, f"{field}.{key}", "missing")
        name = _check_name(spec["name"], None, f"{field}.name")
        if name in seen:
            raise CaptureError(None, f"{field}.name", f"duplicate name {name!r}")
        seen.add(name)
        spec = {"name": name, "K": _check_K(spec["K"], None, f"{field}.K"),
                "R": _check_R(spec["R"], None, f"{field}.R"),
                "t": _check_t(spec["t"], None, f"{field}.t"),
                "holdout": _check_holdout(spec.get("holdout", False), None, f"{field}.holdout")}

        if name in images:
            rgb = np.asarray(images[name])
        elif isinstance(item, View):
            rgb = item.read_image()
        else:
            raise CaptureError(None, f"images[{name!r}]", "missing photograph for this view")
        if rgb.ndim != 3 or rgb.shape[2] != 3 or 0 in rgb.shape:
            raise CaptureError(None, f"images[{name!r}]", f"expected shape (height, width, 3), "
                                                          f"got {rgb.shape}")
        bad = int(np.count_nonzero(~np.isfinite(rgb)))
        if bad:
            raise CaptureError(None, f"images[{name!r}]", f"{bad} non-finite values (NaN or Inf)")

        mask = None
        if name in masks:
            mask = np.asarray(masks[name])
            if mask.ndim == 3:
                mask = np.any(mask != 0, axis=-1)
            if mask.shape != rgb.shape[:2]:
                raise CaptureError(None, f"masks[{name!r}]", f"shape {mask.shape} differs from "
                                                             f"the photograph's {rgb.shape[:2]}")
            if not np.any(mask):
                raise CaptureError(None, f"masks[{name!r}]", "mask is all zero")
        elif isinstance(item, View) and item.mask is not None:
            mask = item.read_mask()

        sd = None
        if name in noise:
            sd = _check_noise(noise[name], rgb.shape, None, f"noise[{name!r}]")
        elif isinstance(item, View) and item.noise is not None and name not in images:
            sd = item.read_noise()
        prepared.append((spec, rgb, mask, sd))
    for what, given in (("images", images), ("masks", masks), ("processing", processing),
                        ("noise", noise)):
        if unused := sorted(set(given) - seen):
            raise CaptureError(None, f"{what}[{unused[0]!r}]", "no view has this name")

    folder.mkdir(parents=True, exist_ok=True)
    saved: list[View] = []
    for spec, rgb, mask, sd in prepared:
        image_path = folder / f"{spec['name']}.exr"
        write_exr(image_path, rgb)
        mask_path = noise_path = None
        if mask is not None:
            mask_path = folder / f"{spec['name']}_mask.png"
            write_mask(mask_path, mask)
        if sd is not None:
            noise_path = folder / "noise" / f"{spec['name']}.exr"
            noise_path.parent.mkdir(exist_ok=True)
            write_exr(noise_path, sd)
        saved.append(View(image=image_path, width=rgb.shape[1], height=rgb.shape[0],
                          mask=mask_path, processing=processing.get(spec["name"]),
                          noise=noise_path, **spec))

    text = '{\n  "views": [\n' + ",\n".join(_json_view(v, folder) for v in saved) + "\n  ]"
    if any(blur_px):
        # Only when there is a blur: captures without one stay as every reader knows them.
        text += f',\n  "blur_px": {json.dumps(list(blur_px))}'
    if processing:
        text += _json_map("processing", {name: p.to_json() for name, p in processing.items()})
    if any(v.noise is not None for v in saved):
        text += _json_map("noise", {v.name: f"noise/{v.noise.name}" for v in saved
                                    if v.noise is not None})
    text += "\n}\n"
    tmp = folder / f".{CAMERAS_FILE}.tmp"
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, folder / CAMERAS_FILE)
    return load_capture(folder)
