"""The LEDs' radial attenuation and intensities from a grey board (issue 27, part 3).

A flat Lambertian board of known albedo ``rho`` (a grey card) lies on the turntable, its corners
known in the object frame. Lit by LED ``k`` alone, a board pixel reads

``pixel = gain * t * rho / pi * cos(theta_l) * I_k * (level / 255) * A(theta) / d^2``

(:mod:`~abs.lightstage.measure`'s model with ``f_r = rho / pi``), ``theta`` the angle of the pixel's
point off the LED's axis and ``d`` its distance. With the LED positions known (calibrated first,
:mod:`~abs.lightstage.ledball`) every factor but ``I_k A(theta)`` is known, so each pixel gives
``y = I_k A(theta)``. With ``A = cos^m`` this is linear in logarithms,
``log y = log I_k + m log cos(theta)``: ``m`` is one slope shared by every LED (its pixels compared
within each LED, so the unknown ``I_k`` drop out), then ``log I_k`` is each LED's mean of
``log y - m log cos(theta)`` per channel.

The intensities come out in the units of the geometry file's gain (pixel value per unit radiance
per second) and the board's albedo: common to every LED, so the reflectance measured with them is
right up to the albedo's own error, a factor shared by every measurement.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from abs.errors import InputError
from abs.lightstage.attenuation import Attenuation
from abs.lightstage.geometry import Led, RigGeometry
from abs.lightstage.measure import MIN_COS, led_irradiance, pose_view
from abs.lightstage.raycast import MeshTracer
from abs.lightstage.session import SATURATION

__all__ = ["LedFrame", "board_tracer", "board_samples", "BoardFit", "fit_board"]


@dataclass(frozen=True)
class LedFrame:
    """One calibration frame (of the grey board or the mirror ball) lit by one LED.

    Attributes
    ----------
    angle_deg : float
        Turntable angle, degrees.
    light : str
        LED name.
    level : int
        LED level, 0..255.
    exposure_s : float
        Exposure, seconds.
    image : np.ndarray
        (H, W, 3) linear pixel values in [0, 1].
    camera : int
        Camera index in the geometry file.
    """

    angle_deg: float
    light: str
    level: int
    exposure_s: float
    image: np.ndarray
    camera: int = 0


def board_tracer(corners: np.ndarray) -> MeshTracer:
    """The board (four corners in order around it, object frame, metres) as two triangles."""
    c = np.asarray(corners, np.float64)
    return MeshTracer(c, np.array([[0, 1, 2], [0, 2, 3]]))


def board_samples(geometry: RigGeometry, tracer: MeshTracer, frames: list[LedFrame],
                  albedo: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per LED, ``(cos theta off its axis (N,), y = I_k A(theta) (N, 3))`` over its board pixels.

    Pixels clipped (>= :data:`~abs.lightstage.session.SATURATION`), shadowed, grazing
    (``n.l`` or ``n.v`` < :data:`~abs.lightstage.measure.MIN_COS`) or not positive are left out.
    """
    # The geometry with unit intensities and no attenuation: led_irradiance then returns
    # (level/255) / d^2 and the cosine off the axis is computed here, so neither unknown is assumed.
    bare = replace(geometry, attenuation=Attenuation(0.0),
                   leds={k: Led(v.position, v.axis, np.ones(3)) for k, v in geometry.leds.items()})
    albedo = np.asarray(albedo, np.float64)
    out: dict[str, list] = {}
    view, key = None, None
    for f in frames:
        if f.light not in geometry.leds:
            raise InputError(None, "frames.light", f"board frame's light {f.light!r} is not in the geometry file")
        h, w = f.image.shape[:2]
        if key != (f.camera, f.angle_deg, w, h):
            cam = bare.cameras[f.camera]
            sized = bare if (w, h) == (cam.width, cam.height) else bare.with_image_size(f.camera, w, h)
            view, key = pose_view(sized, tracer, f.camera, f.angle_deg), (f.camera, f.angle_deg, w, h)
        wi, factor = led_irradiance(bare, tracer, view, f.light, f.level)
        n = view.hits.normal
        cos_l, cos_v = np.sum(n * wi, 1), np.sum(n * view.view, 1)
        pix = f.image.reshape(-1, 3)[view.pixel].astype(np.float64)
        keep = ((factor.min(1) > 0) & (cos_l > MIN_COS) & (cos_v > MIN_COS)
                & np.all(pix < SATURATION, 1) & np.all(pix > 0, 1))
        axis = geometry.leds[f.light].axis @ view.to_object.T
        cos_off = -wi[keep] @ axis
        y = pix[keep] / (geometry.gain * f.exposure_s * albedo / np.pi * cos_l[keep, None] * factor[keep])
        out.setdefault(f.light, []).append((cos_off, y))
    return {k: (np.concatenate([a for a, _ in v]), np.concatenate([b for _, b in v])) for k, v in out.items()}


@dataclass(frozen=True)
class BoardFit:
    """The board's answer: a ``cos^m`` profile shared by the LEDs and each LED's intensity.

    Attributes
    ----------
    exponent : float
        ``m`` of the radial attenuation ``cos(theta)^m``.
    intensity : dict
        LED name -> (3,) on-axis RGB intensity at full level, units of the gain and albedo.
    pixels : dict
        LED name -> number of board pixels used.
    max_angle_deg : float
        Largest angle off an LED's axis on the board: the profile is measured up to here only.
    rms_log_residual : float
        RMS of ``log y`` about the fit (relative error of the model per pixel).
    """

    exponent: float
    intensity: dict[str, np.ndarray]
    pixels: dict[str, int]
    max_angle_deg: float
    rms_log_residual: float


def fit_board(samples: dict[str, tuple[np.ndarray, np.ndarray]], min_pixels: int = 20) -> BoardFit:
    """Fit ``y = I_k cos(theta)^m`` to :func:`board_samples` (see the module docstring).

    LEDs with fewer than ``min_pixels`` pixels are left out (their intensity stays unknown).
    """
    used = {k: v for k, v in samples.items() if len(v[0]) >= min_pixels}
    if not used:
        raise InputError(None, "board", f"no LED lights at least {min_pixels} unclipped board pixels")
    xs, ys = [], []
    for cos_off, y in used.values():
        x = np.log(np.clip(cos_off, 1e-6, 1.0))
        ly = np.log(y)
        xs.append(np.repeat((x - x.mean())[:, None], 3, 1))
        ys.append(ly - ly.mean(0))
    X, Y = np.concatenate(xs).ravel(), np.concatenate(ys).ravel()
    denom = float(X @ X)
    if denom <= 0.0:
        raise InputError(None, "board", "every board pixel is at one angle off its LED's axis: "
                         "the attenuation cannot be measured (a larger board)")
    m = float(X @ Y) / denom
    intensity, pixels, res = {}, {}, []
    for k, (cos_off, y) in used.items():
        r = np.log(y) - m * np.log(np.clip(cos_off, 1e-6, 1.0))[:, None]
        intensity[k] = np.exp(r.mean(0))
        pixels[k] = len(cos_off)
        res.append((r - r.mean(0)).ravel())
    max_angle = max(float(np.rad2deg(np.arccos(np.clip(v[0].min(), -1, 1)))) for v in used.values())
    return BoardFit(m, intensity, pixels, max_angle, float(np.sqrt(np.mean(np.concatenate(res) ** 2))))
