"""Light calibration (issue 27, part 3): a calibration folder and the geometry file, refined.

Format ``"abs-lightstage-calibration/1"``, ``calibration.json`` in the folder (object frame at
turntable angle 0, metres, like the mesh):

.. code-block:: json

    {"format": "abs-lightstage-calibration/1",
     "ball": {"center": [0.04, 0.0, 0.0], "radius": 0.015},
     "board": {"corners": [[x, y, z], [...], [...], [...]], "albedo": [0.18, 0.18, 0.18]},
     "frames": [{"target": "ball", "angle_deg": 0.0, "light": "b00l00", "level": 255,
                 "exposure_s": 0.01, "file": "ball/000-b00l00.exr"},
                {"target": "board", "angle_deg": 0.0, "light": "b00l00", "level": 255,
                 "exposure_s": 0.02, "file": "board/b00l00.exr"}]}

- ball: a mirror (chrome) ball on the turntable, its centre at angle 0 and its radius;
- board: a flat grey board, its corners in order around it, and its albedo (R, G, B);
- frames: one LED on per frame (``camera`` optional, default 0); file paths relative to the folder.

:func:`calibrate` refines the geometry file in three steps, in this order because each needs the
one before: LED positions from the ball's highlights (:mod:`~abs.lightstage.ledball`), then the
``cos^m`` radial attenuation and the RGB intensities from the board
(:mod:`~abs.lightstage.greyboard`), whose model needs the positions. LED axes, cameras, turntable
and gain are kept from the geometry file.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from abs.errors import InputError, read_json
from abs.io.images import read_image
from abs.lightstage.attenuation import Attenuation
from abs.lightstage.geometry import RigGeometry, finite_array
from abs.lightstage.greyboard import LedFrame, board_samples, board_tracer, fit_board
from abs.lightstage.ledball import highlight_centroid, reflected_ray, triangulate_led

__all__ = ["CALIBRATION_FORMAT", "CalibrationData", "read_calibration", "calibrate"]

CALIBRATION_FORMAT = "abs-lightstage-calibration/1"


@dataclass(frozen=True)
class CalibrationData:
    """What a calibration folder holds (see the module docstring); images loaded.

    Attributes
    ----------
    ball_center : np.ndarray or None
        (3,) ball centre at turntable angle 0, object frame, metres.
    ball_radius : float or None
        Metres.
    board_corners : np.ndarray or None
        (4, 3) board corners, object frame, metres.
    board_albedo : np.ndarray or None
        (3,) board albedo.
    ball_frames, board_frames : list of LedFrame
        Frames of the ball and of the board (:class:`~abs.lightstage.greyboard.LedFrame`).
    """

    ball_center: np.ndarray | None
    ball_radius: float | None
    board_corners: np.ndarray | None
    board_albedo: np.ndarray | None
    ball_frames: list[LedFrame]
    board_frames: list[LedFrame]


def read_calibration(folder: str | Path) -> CalibrationData:
    """Read ``folder/calibration.json`` and its frames; malformed fields are :class:`InputError`."""
    folder = Path(folder)
    path = folder / "calibration.json"
    data = read_json(path, what="calibration file")
    if data.get("format") != CALIBRATION_FORMAT:
        raise InputError(path, "format", f"expected {CALIBRATION_FORMAT!r}, got {data.get('format')!r}")
    center = radius = corners = albedo = None
    if "ball" in data:
        ball = data["ball"]
        if not isinstance(ball, dict):
            raise InputError(path, "ball", "expected an object with center and radius")
        center = finite_array(path, "ball.center", ball.get("center"), (3,))
        radius = float(finite_array(path, "ball.radius", ball.get("radius"), ()))
        if not radius > 0:
            raise InputError(path, "ball.radius", f"must be > 0, got {radius}")
    if "board" in data:
        board = data["board"]
        if not isinstance(board, dict):
            raise InputError(path, "board", "expected an object with corners and albedo")
        corners = finite_array(path, "board.corners", board.get("corners"), (4, 3))
        albedo = finite_array(path, "board.albedo", board.get("albedo"), (3,))
        if not np.all(albedo > 0):
            raise InputError(path, "board.albedo", f"must be > 0 per channel, got {albedo.tolist()}")
    frames = data.get("frames")
    if not isinstance(frames, list) or not frames:
        raise InputError(path, "frames", "expected a non-empty array")
    ball_frames, board_frames = [], []
    for i, f in enumerate(frames):
        name = f"frames[{i}]"
        if not isinstance(f, dict):
            raise InputError(path, name, "expected an object")
        target = f.get("target")
        if target not in ("ball", "board"):
            raise InputError(path, f"{name}.target", f"expected 'ball' or 'board', got {target!r}")
        if target == "ball" and center is None or target == "board" and corners is None:
            raise InputError(path, target, f"{name} is a {target} frame but the file has no {target!r}")
        light = f.get("light")
        if not isinstance(light, str):
            raise InputError(path, f"{name}.light", "expected an LED name")
        level, exposure = f.get("level", 255), f.get("exposure_s")
        if not isinstance(level, int) or not 0 < level <= 255:
            raise InputError(path, f"{name}.level", f"expected an integer in 1..255, got {level!r}")
        if not isinstance(exposure, (int, float)) or not exposure > 0:
            raise InputError(path, f"{name}.exposure_s", f"expected a number > 0, got {exposure!r}")
        angle = float(finite_array(path, f"{name}.angle_deg", f.get("angle_deg"), ()))
        file = f.get("file")
        if not isinstance(file, str):
            raise InputError(path, f"{name}.file", "expected a path relative to the folder")
        image = read_image(folder / file)
        (ball_frames if target == "ball" else board_frames).append(
            LedFrame(angle, light, level, float(exposure), image, int(f.get("camera", 0))))
    return CalibrationData(center, radius, corners, albedo, ball_frames, board_frames)


def _camera(geometry: RigGeometry, frame: LedFrame):
    """The frame's camera, resized to the frame's image (calibration frames may be full size)."""
    if not 0 <= frame.camera < len(geometry.cameras):
        raise InputError(None, "frames.camera", f"camera {frame.camera} is not in the geometry file")
    cam = geometry.cameras[frame.camera]
    h, w = frame.image.shape[:2]
    try:
        return cam if (w, h) == (cam.width, cam.height) else cam.resized(w, h)
    except ValueError as exc:
        raise InputError(None, "frames.file", f"a {frame.light} frame at {frame.angle_deg:g} deg: {exc}") from None


def calibrate(geometry: RigGeometry, data: CalibrationData, sigma_prior_m: float = 0.02,
              sigma_direction_rad: float | None = None) -> tuple[RigGeometry, dict]:
    """The geometry refined by the calibration frames, and a report (JSON-ready).

    Parameters
    ----------
    geometry : RigGeometry
        The rig's geometry file (LED positions as designed).
    data : CalibrationData
        Ball and/or board frames.
    sigma_prior_m : float
        Uncertainty of the geometry file's positions, metres.
    sigma_direction_rad : float or None
        Uncertainty of a highlight line's direction; None: estimated per LED from its lines
        (:func:`~abs.lightstage.ledball.triangulate_led`).

    Returns
    -------
    geometry : RigGeometry
        Positions refined where the ball gave at least one highlight line; attenuation and
        intensities replaced where the board was seen.
    report : dict
        Per LED: highlight lines, shift from the geometry file (mm), line RMS (mm), board pixels;
        the fitted exponent and the angle range the board covered.
    """
    for f in [*data.ball_frames, *data.board_frames]:
        if f.light not in geometry.leds:
            raise InputError(None, "frames.light", f"calibration frame's light {f.light!r} is not in "
                             "the geometry file")
    leds = dict(geometry.leds)
    report: dict[str, Any] = {"leds": {k: {} for k in sorted(leds)}}
    if data.ball_frames:
        lines: dict[str, list] = {k: [] for k in leds}
        for f in data.ball_frames:
            rot, c = geometry.object_to_world(f.angle_deg)
            center = rot @ (data.ball_center - c) + c
            cam = _camera(geometry, f)
            uv = highlight_centroid(f.image, cam, center, data.ball_radius)
            ray = None if uv is None else reflected_ray(cam, center, data.ball_radius, uv)
            if ray is not None:
                lines[f.light].append(ray)
        for k, ls in lines.items():
            pts = np.array([p for p, _, _ in ls]).reshape(-1, 3)
            dirs = np.array([r for _, r, _ in ls]).reshape(-1, 3)
            fix = triangulate_led(pts, dirs, leds[k].position, sigma_prior_m, sigma_direction_rad,
                                  np.array([c for _, _, c in ls]))
            if fix.lines:
                leds[k] = replace(leds[k], position=fix.position)
            report["leds"][k].update(
                highlight_lines=fix.lines,
                shift_mm=round(1e3 * float(np.linalg.norm(fix.position - geometry.leds[k].position)), 3),
                line_rms_mm=round(1e3 * fix.rms_line_distance_m, 3) if fix.lines else None,
                sigma_direction_rad=float(f"{fix.sigma_direction_rad:.3g}"))
        report["leds_without_highlight"] = sorted(k for k, ls in lines.items() if not ls)
    attenuation = geometry.attenuation
    if data.board_frames:
        positioned = replace(geometry, leds=leds)
        samples = board_samples(positioned, board_tracer(data.board_corners), data.board_frames,
                                data.board_albedo)
        fit = fit_board(samples)
        attenuation = Attenuation(fit.exponent)
        for k, i in fit.intensity.items():
            leds[k] = replace(leds[k], intensity=i)
            report["leds"][k].update(board_pixels=fit.pixels[k], intensity=i.round(5).tolist())
        report["attenuation"] = {"kind": "cos_power", "exponent": round(fit.exponent, 4),
                                 "measured_up_to_deg": round(fit.max_angle_deg, 2),
                                 "rms_log_residual": round(fit.rms_log_residual, 5)}
        report["leds_without_board"] = sorted(set(leds) - set(fit.intensity))
    return replace(geometry, leds=leds, attenuation=attenuation), report
