"""A rig session folder's LED frames (rig/README.md, "Session folder"), HDR brackets merged.

The folder is read, not written: ``manifest.json`` (format ``abs-rig-session/1``) lists every
frame in place with its turntable position and angle, light, level and exposure. The global-light
frames are for photogrammetry and are skipped here; every LED's bracket of exposures at one
turntable position is merged into one image of ``pixel / exposure_s`` (pixel value per second).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abs.errors import InputError, read_json
from abs.io.images import read_image

__all__ = ["SESSION_FORMAT", "LightGroup", "read_session_groups", "merge_bracket", "SATURATION"]

SESSION_FORMAT = "abs-rig-session/1"

SATURATION = 0.98
"""Pixel values at or above this are taken as clipped (a sensor's full well at 1)."""


@dataclass(frozen=True)
class LightGroup:
    """One LED at one turntable position: its frames' files and exposures.

    Attributes
    ----------
    position : int
        Turntable position index.
    angle_deg : float
        Turntable angle, degrees.
    light : str
        LED name (``b01l07``), a key of the geometry file's ``leds``.
    level : int
        LED level, 0..255.
    files : tuple of Path
        The bracket's images.
    exposures_s : tuple of float
        Their exposures, seconds.
    camera : int
        Index of the camera in the geometry file (0 for the one-camera rig).
    """

    position: int
    angle_deg: float
    light: str
    level: int
    files: tuple[Path, ...]
    exposures_s: tuple[float, ...]
    camera: int = 0

    def image(self) -> np.ndarray:
        """The merged bracket (H, W, 3), pixel value per second; NaN where every exposure clipped."""
        return merge_bracket([read_image(f) for f in self.files], self.exposures_s)


def merge_bracket(images: list[np.ndarray], exposures_s: tuple[float, ...]) -> np.ndarray:
    """Merge an exposure bracket into pixel value per second.

    Each unclipped pixel gives ``value / exposure``; they are averaged with weights equal to the
    exposure, so the longest unclipped exposure (best signal to noise) counts most. A pixel clipped
    in every exposure is NaN: its value is unknown.
    """
    num = np.zeros(images[0].shape, np.float64)
    den = np.zeros(images[0].shape, np.float64)
    for img, t in zip(images, exposures_s):
        ok = np.asarray(img) < SATURATION
        num += np.where(ok, np.asarray(img, np.float64), 0.0)
        den += np.where(ok, t, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def read_session_groups(folder: str | Path) -> list[LightGroup]:
    """The LED light groups of a session, in plan order.

    Raises
    ------
    InputError
        The folder or its manifest is missing or malformed, a listed frame file is missing, or
        the session has no LED frames.
    """
    # Absolute, so the paths recorded in a light-stage folder work from any directory.
    folder = Path(folder).resolve()
    if not folder.is_dir():
        raise InputError(folder, "", "session folder not found")
    manifest_path = folder / "manifest.json"
    if not manifest_path.exists():
        raise InputError(manifest_path, "", "not found: not a rig session folder (made by "
                         "'abs rig capture')")
    manifest = read_json(manifest_path, what="session manifest")
    if manifest.get("format") != SESSION_FORMAT:
        raise InputError(manifest_path, "format", f"expected {SESSION_FORMAT!r}, got "
                         f"{manifest.get('format')!r}")
    frames = manifest.get("frames")
    if not isinstance(frames, list):
        raise InputError(manifest_path, "frames", "expected an array")
    groups: dict[tuple[int, str], dict] = {}
    for i, f in enumerate(frames):
        if not isinstance(f, dict):
            raise InputError(manifest_path, f"frames[{i}]", "expected an object")
        if f.get("light_kind") != "led":
            continue
        try:
            key = (int(f["position"]), str(f["light"]))
            angle, level, exposure = float(f["angle_deg"]), int(f["level"]), float(f["exposure_s"])
            path = folder / str(f["file"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(manifest_path, f"frames[{i}]", f"malformed frame record ({exc})") from None
        if not path.exists():
            raise InputError(manifest_path, f"frames[{i}].file", f"{path} not found")
        g = groups.setdefault(key, {"angle": angle, "level": level, "files": [], "exposures": [],
                                    "camera": int(f.get("camera", 0))})
        g["files"].append(path)
        g["exposures"].append(exposure)
    if not groups:
        raise InputError(manifest_path, "frames", "no LED frames in this session (nothing captured yet?)")
    return [LightGroup(pos, g["angle"], light, g["level"], tuple(g["files"]), tuple(g["exposures"]),
                       g["camera"]) for (pos, light), g in groups.items()]
