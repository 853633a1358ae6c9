"""Simulated calibration frames whose truth is known (tests, benchmark, notebook).

A "true" rig differs from its geometry file as a hand-built dome would
(:func:`perturbed_rig`): LEDs displaced by a few millimetres, intensities spread by tens of
percent, a narrower radial profile than the file's ``cos^4``. Its calibration frames:

- **ball** (:func:`ball_frame`): the highlight of a mirror ball. The point of the ball that
  reflects the LED into the camera is found forwards, by iterating the half-vector condition
  ``n = normalise(unit(C - p) + unit(L - p))`` to its fixed point (a different route from the
  calibration's, which reflects the camera ray through the highlight). Its image is a Gaussian spot
  (the lens's blur, ``psf_px``) at the point's projection, peak ``0.5 I att`` (not radiometric: only
  the spot's position carries information);
- **board** (:func:`board_frame`): the grey board rendered with
  :func:`~abs.lightstage.render.render_view` (Lambert, the true rig's positions, intensities and
  profile).

Both get the benchmark's sensor noise (Gaussian, sigma ``0.003 + 1 %`` of the value) and clipping.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from abs.camera.pinhole import camera_center, project
from abs.io.images import write_exr
from abs.lightstage.attenuation import Attenuation
from abs.lightstage.geometry import RigGeometry
from abs.lightstage.measure import pose_view
from abs.lightstage.raycast import MeshTracer
from abs.lightstage.render import AnalyticMaterial, render_view

__all__ = ["perturbed_rig", "ball_frame", "board_frame", "add_noise", "write_calibration_folder",
           "BALL_CENTER", "BALL_RADIUS", "BOARD_CORNERS", "BOARD_ALBEDO"]

BALL_CENTER = np.array([0.04, 0.0, 0.0])
"""The simulated ball's centre at angle 0, object frame (m): off the axis, so it circles."""
BALL_RADIUS = 0.025
BOARD_CORNERS = np.array([[-0.12, 0.0, -0.12], [-0.12, 0.0, 0.12], [0.12, 0.0, 0.12], [0.12, 0.0, -0.12]])
"""A 24 cm grey board lying on the turntable (y = 0, facing up), object frame (m)."""
BOARD_ALBEDO = np.array([0.18, 0.18, 0.18])


def perturbed_rig(geometry: RigGeometry, rng: np.random.Generator, position_sigma_m: float = 0.008,
                  intensity_spread: float = 0.25, exponent: float = 10.0) -> RigGeometry:
    """A true rig near ``geometry``: positions + N(0, sigma) per axis, intensities x U(1 +- spread)
    per LED (and +- spread/5 per channel), attenuation ``cos^exponent``; axes kept."""
    leds = {}
    for k in sorted(geometry.leds):
        led = geometry.leds[k]
        scale = rng.uniform(1 - intensity_spread, 1 + intensity_spread)
        tint = rng.uniform(1 - intensity_spread / 5, 1 + intensity_spread / 5, 3)
        leds[k] = replace(led, position=led.position + rng.normal(0.0, position_sigma_m, 3),
                          intensity=led.intensity * scale * tint)
    return replace(geometry, leds=leds, attenuation=Attenuation(exponent))


def add_noise(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sensor noise (sigma 0.003 + 1 % of the value), clipped to [0, 1]."""
    return np.clip(image + rng.normal(size=image.shape) * (0.003 + 0.01 * image), 0.0, 1.0).astype(np.float32)


def _specular_point(eye: np.ndarray, led: np.ndarray, center: np.ndarray, radius: float) -> np.ndarray:
    n = eye - center
    n /= np.linalg.norm(n)
    for _ in range(200):
        p = center + radius * n
        a, b = eye - p, led - p
        h = a / np.linalg.norm(a) + b / np.linalg.norm(b)
        n_new = h / np.linalg.norm(h)
        if np.linalg.norm(n_new - n) < 1e-13:
            break
        n = n_new
    return center + radius * n


def ball_frame(truth: RigGeometry, angle_deg: float, light: str, rng: np.random.Generator,
               center0: np.ndarray = BALL_CENTER, radius: float = BALL_RADIUS, psf_px: float = 0.8,
               camera: int = 0, scale: int = 8) -> np.ndarray:
    """A noisy frame of the mirror ball at ``angle_deg`` lit by LED ``light``, ``scale`` times the
    camera's width and height (calibration frames at the sensor's full size: a highlight's
    centroid must be found to about 0.01 session pixel for millimetres at the LED)."""
    cam = truth.cameras[camera]
    cam = cam.resized(cam.width * scale, cam.height * scale)
    rot, c = truth.object_to_world(angle_deg)
    center = rot @ (np.asarray(center0) - c) + c
    led = truth.leds[light]
    p = _specular_point(camera_center(cam.R, cam.t), led.position, center, radius)
    u, v = project(cam.K, cam.R, cam.t, p[None, :])[0]
    image = np.zeros((cam.height, cam.width, 3))
    # The spot is drawn in a window of +-5 sigma: the rest of the frame is noise only.
    r = int(np.ceil(5 * psf_px))
    ys = slice(max(0, int(v) - r), min(cam.height, int(v) + r + 2))
    xs = slice(max(0, int(u) - r), min(cam.width, int(u) + r + 2))
    vv, uu = np.mgrid[ys, xs]
    spot = np.exp(-((uu - u) ** 2 + (vv - v) ** 2) / (2.0 * psf_px ** 2))
    to_ball = center - led.position
    att = truth.attenuation(np.array(led.axis @ to_ball / np.linalg.norm(to_ball)))
    image[ys, xs] = 0.5 * spot[:, :, None] * (led.intensity * att)[None, None, :]
    return add_noise(image, rng)


def board_frame(truth: RigGeometry, tracer: MeshTracer, angle_deg: float, light: str,
                exposure_s: float, rng: np.random.Generator, albedo: np.ndarray = BOARD_ALBEDO,
                camera: int = 0) -> np.ndarray:
    """A noisy (H, W, 3) frame of the Lambertian board lit by LED ``light`` at full level."""
    material = AnalyticMaterial("lambert", lambda pts: np.broadcast_to(
        np.asarray(albedo, np.float64)[None, :, None], (len(pts), 3, 1)))
    view = pose_view(truth, tracer, camera, angle_deg)
    return add_noise(render_view(truth, tracer, view, light, 255, exposure_s, material), rng)


def write_calibration_folder(truth: RigGeometry, folder: str | Path, ball_angles_deg,
                             rng: np.random.Generator, board_exposure_s: float = 0.02,
                             ball_scale: int = 8) -> Path:
    """Render a calibration folder (``calibration.json``, ``ball/*.exr``, ``board/*.exr``) of ``truth``.

    Ball frames at every angle of ``ball_angles_deg`` for every LED, ``ball_scale`` times the
    camera's size; one board frame per LED at angle 0, at the camera's size. Returns the folder.
    """
    from abs.lightstage.greyboard import board_tracer

    folder = Path(folder)
    (folder / "ball").mkdir(parents=True, exist_ok=True)
    (folder / "board").mkdir(exist_ok=True)
    frames = []
    for a in ball_angles_deg:
        for k in sorted(truth.leds):
            name = f"ball/{a:07.2f}-{k}.exr"
            write_exr(folder / name, ball_frame(truth, float(a), k, rng, scale=ball_scale))
            frames.append({"target": "ball", "angle_deg": float(a), "light": k, "level": 255,
                           "exposure_s": 0.01, "file": name})
    tracer = board_tracer(BOARD_CORNERS)
    for k in sorted(truth.leds):
        name = f"board/{k}.exr"
        write_exr(folder / name, board_frame(truth, tracer, 0.0, k, board_exposure_s, rng))
        frames.append({"target": "board", "angle_deg": 0.0, "light": k, "level": 255,
                       "exposure_s": board_exposure_s, "file": name})
    meta = {"format": "abs-lightstage-calibration/1",
            "ball": {"center": BALL_CENTER.tolist(), "radius": BALL_RADIUS},
            "board": {"corners": BOARD_CORNERS.tolist(), "albedo": BOARD_ALBEDO.tolist()},
            "frames": frames}
    (folder / "calibration.json").write_text(json.dumps(meta, indent=1) + "\n")
    return folder
