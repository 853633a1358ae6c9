"""The rig's geometry file: cameras, turntable, LEDs and sensor, everything that turns a frame's
pixels into reflectance.

Format ``"abs-lightstage-geometry/1"`` (JSON), world frame of docs/conventions.md (metres, +y up):

.. code-block:: json

    {"format": "abs-lightstage-geometry/1",
     "cameras": [{"K": [[...], [...], [...]], "R": [[...]], "t": [x, y, z], "width": 64, "height": 48}],
     "turntable": {"axis": [0, 1, 0], "center": [0, 0, 0]},
     "leds": {"b00l00": {"position": [x, y, z], "axis": [dx, dy, dz], "intensity": [1, 1, 1]}, ...},
     "attenuation": {"kind": "cos_power", "exponent": 4},
     "gain": 100.0}

- cameras: OpenCV pinhole, ``x_cam = R X_world + t`` (abs.camera.pinhole); the cameras stand still
  and the object turns.
- turntable: turning the table by ``a`` degrees rotates the object by ``a`` about ``axis`` (right
  hand) through ``center``; the mesh is given in the object's frame at angle 0.
- leds: position (metres), unit axis the LED points along, on-axis radiant intensity at full
  level per RGB channel (W/sr; any common unit works, it divides out of the reflectance only if
  it is right). An LED at level ``L`` of 255 emits ``L / 255`` of it.
- attenuation: :class:`~abs.lightstage.attenuation.Attenuation`, shared by every LED (``cos_power``
  with an ``exponent``, or ``table`` with ``angles_deg`` and ``values``); absent: none (1 everywhere).
- gain: pixel value per unit radiance per second of exposure, so a pixel is
  ``gain * exposure_s * radiance`` (linear, before clipping at 1).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from abs.errors import InputError, read_json
from abs.lightstage.attenuation import Attenuation

__all__ = ["FORMAT", "Camera", "Led", "RigGeometry", "read_geometry", "write_geometry",
           "turntable_rotation", "finite_array"]

FORMAT = "abs-lightstage-geometry/1"


@dataclass(frozen=True)
class Camera:
    """A calibrated pinhole camera (OpenCV convention), fixed in the world.

    Parameters
    ----------
    K : np.ndarray
        (3, 3) intrinsics, pixels.
    R : np.ndarray
        (3, 3) world-to-camera rotation.
    t : np.ndarray
        (3,) world-to-camera translation, metres.
    width, height : int
        Image size, pixels.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int

    def resized(self, width: int, height: int) -> Camera:
        """This camera taking images of ``width x height`` pixels (the same field of view).

        Calibration frames may be taken at the sensor's full size while a session is binned
        down: the intrinsics scale by ``s = width / self.width`` about the pixel-centre
        convention's origin, ``u' = s (u + 0.5) - 0.5``. Raises ValueError if the aspect differs.
        """
        s = width / self.width
        if abs(height / self.height - s) > 1e-9:
            raise ValueError(f"image {width}x{height} is not a scaled {self.width}x{self.height}")
        S = np.array([[s, 0.0, 0.5 * s - 0.5], [0.0, s, 0.5 * s - 0.5], [0.0, 0.0, 1.0]])
        return Camera(S @ self.K, self.R, self.t, width, height)


@dataclass(frozen=True)
class Led:
    """One LED: position (metres), unit axis, on-axis RGB intensity at full level (W/sr)."""

    position: np.ndarray
    axis: np.ndarray
    intensity: np.ndarray


@dataclass(frozen=True)
class RigGeometry:
    """Cameras, turntable, LEDs and sensor gain of a light stage (see the module docstring)."""

    cameras: tuple[Camera, ...]
    leds: dict[str, Led]
    turntable_axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    turntable_center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    attenuation: Attenuation = field(default_factory=Attenuation)
    gain: float = 1.0

    def object_to_world(self, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """``(M, c)`` with ``X_world = M (X_object - c) + c`` at turntable angle ``angle_deg``."""
        return turntable_rotation(self.turntable_axis, angle_deg), self.turntable_center

    def with_image_size(self, camera: int, width: int, height: int) -> RigGeometry:
        """This geometry with camera ``camera`` taking ``width x height`` images
        (:meth:`Camera.resized`)."""
        cams = list(self.cameras)
        cams[camera] = cams[camera].resized(width, height)
        return replace(self, cameras=tuple(cams))

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "cameras": [{"K": c.K.tolist(), "R": c.R.tolist(), "t": c.t.tolist(),
                         "width": c.width, "height": c.height} for c in self.cameras],
            "turntable": {"axis": self.turntable_axis.tolist(), "center": self.turntable_center.tolist()},
            "leds": {name: {"position": led.position.tolist(), "axis": led.axis.tolist(),
                            "intensity": led.intensity.tolist()} for name, led in self.leds.items()},
            "attenuation": self.attenuation.to_dict(),
            "gain": self.gain,
        }


def turntable_rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle_deg`` about the unit ``axis`` (right hand, Rodrigues)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    a = np.deg2rad(angle_deg)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * kx + (1.0 - np.cos(a)) * kx @ kx


def finite_array(source: Path, name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as finite float64 numbers of ``shape``, else an InputError naming ``source`` and ``name``."""
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(source, name, f"expected numbers of shape {shape}") from None
    if out.shape != shape or not np.all(np.isfinite(out)):
        raise InputError(source, name, f"expected finite numbers of shape {shape}, got {np.shape(value)}")
    return out


def _unit(source: Path, name: str, value: Any) -> np.ndarray:
    v = finite_array(source, name, value, (3,))
    norm = np.linalg.norm(v)
    if norm == 0.0:
        raise InputError(source, name, "must not be the zero vector")
    return v / norm


def _attenuation(source: Path, data: Any) -> Attenuation:
    if not isinstance(data, dict):
        raise InputError(source, "attenuation", "expected an object")
    kind = data.get("kind")
    if kind == "cos_power":
        exponent = data.get("exponent")
        if not isinstance(exponent, (int, float)) or exponent < 0:
            raise InputError(source, "attenuation.exponent", "expected a number >= 0")
        return Attenuation(float(exponent))
    if kind == "table":
        angles = finite_array(source, "attenuation.angles_deg", data.get("angles_deg"),
                        (len(data.get("angles_deg") or []),))
        values = finite_array(source, "attenuation.values", data.get("values"), angles.shape)
        if angles.size < 2 or np.any(np.diff(angles) <= 0):
            raise InputError(source, "attenuation.angles_deg", "expected at least 2 increasing angles")
        return Attenuation(None, tuple(angles), tuple(values))
    raise InputError(source, "attenuation.kind", f"expected 'cos_power' or 'table', got {kind!r}")


def read_geometry(path: str | Path) -> RigGeometry:
    """Read a geometry file; every malformed field is an :class:`InputError` naming it."""
    path = Path(path)
    data = read_json(path, what="geometry file")
    if data.get("format") != FORMAT:
        raise InputError(path, "format", f"expected {FORMAT!r}, got {data.get('format')!r}")
    cams = data.get("cameras")
    if not isinstance(cams, list) or not cams:
        raise InputError(path, "cameras", "expected a non-empty array")
    cameras = []
    for i, c in enumerate(cams):
        if not isinstance(c, dict):
            raise InputError(path, f"cameras[{i}]", "expected an object")
        size = [c.get("width"), c.get("height")]
        if not all(isinstance(s, int) and s > 0 for s in size):
            raise InputError(path, f"cameras[{i}].width", "width and height must be positive integers")
        cameras.append(Camera(finite_array(path, f"cameras[{i}].K", c.get("K"), (3, 3)),
                              finite_array(path, f"cameras[{i}].R", c.get("R"), (3, 3)),
                              finite_array(path, f"cameras[{i}].t", c.get("t"), (3,)), size[0], size[1]))
    leds_data = data.get("leds")
    if not isinstance(leds_data, dict) or not leds_data:
        raise InputError(path, "leds", "expected a non-empty object of LEDs by name")
    leds = {}
    for name, led in leds_data.items():
        if not isinstance(led, dict):
            raise InputError(path, f"leds.{name}", "expected an object")
        intensity = finite_array(path, f"leds.{name}.intensity", led.get("intensity", [1.0, 1.0, 1.0]), (3,))
        leds[name] = Led(finite_array(path, f"leds.{name}.position", led.get("position"), (3,)),
                         _unit(path, f"leds.{name}.axis", led.get("axis")), intensity)
    table = data.get("turntable", {})
    if not isinstance(table, dict):
        raise InputError(path, "turntable", "expected an object")
    gain = data.get("gain", 1.0)
    if not isinstance(gain, (int, float)) or not gain > 0:
        raise InputError(path, "gain", "expected a number > 0")
    return RigGeometry(tuple(cameras), leds,
                       _unit(path, "turntable.axis", table.get("axis", [0.0, 1.0, 0.0])),
                       finite_array(path, "turntable.center", table.get("center", [0.0, 0.0, 0.0]), (3,)),
                       _attenuation(path, data.get("attenuation", {"kind": "cos_power", "exponent": 0})),
                       float(gain))


def write_geometry(geometry: RigGeometry, path: str | Path) -> None:
    """Write ``geometry`` as JSON to ``path``."""
    Path(path).write_text(json.dumps(geometry.to_dict(), indent=1) + "\n", encoding="utf-8")
