"""Images for the simulated camera: a textured Lambertian sphere on the turntable, in numpy.

This is a stand-in, not abs's renderer, and says so in every session it writes
(``"camera_model"`` in the manifest): one ray per pixel centre, an analytic sphere, no
inter-reflection and no sensor noise. It is exact for what it models (a convex Lambertian
sphere lit by point LEDs) and cheap enough for the protocol tests, which need frames whose content
proves which light was on and where the turntable stood, not photorealism. abs's point-light
renderer (``abs.studies.sl_capture.render_point_lit``) takes one scalar intensity per light, so
it cannot apply an LED's radial attenuation per surface point; wiring it in is listed as not done
in rig/README.md.

Frames (docs/conventions.md): world +y up, metres; the turntable axis is +y through the origin,
where the sphere's centre sits; turning the table by ``a`` degrees rotates the object by ``a``
about +y. Images are linear RGB, ``radiance x exposure x gain``, clipped at 1 like a sensor's
full well, so long exposures saturate and an HDR bracket is meaningful.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at, ray_directions

__all__ = ["Dome", "default_dome", "render_frame", "albedo_at"]

SPHERE_RADIUS_M = 0.05
"""Radius of the simulated object, metres."""


@dataclass(frozen=True)
class Dome:
    """The simulated light stage's geometry.

    Parameters
    ----------
    led_positions : np.ndarray
        (boards, leds_per_board, 3) LED positions, metres; every LED's axis points at the origin.
    led_intensity_w_sr : float
        On-axis radiant intensity of an LED at full level, W/sr per channel.
    led_falloff_exponent : float
        Radial attenuation profile ``cos(theta)**m`` about the LED's axis (theta off axis).
    global_irradiance : float
        Irradiance of the global (diffuse, photogrammetry) light at full level, W/m^2, the same
        from every direction so every visible point is lit.
    camera_eye : np.ndarray
        (3,) camera centre, metres; it looks at the origin.
    fov_y_deg : float
        Vertical field of view, degrees.
    gain : float
        Pixel value per (W/(m^2 sr) x s): the sensor's sensitivity.
    """

    led_positions: np.ndarray
    led_intensity_w_sr: float = 1.0
    led_falloff_exponent: float = 4.0
    global_irradiance: float = 2.0
    camera_eye: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.1, 0.45]))
    fov_y_deg: float = 16.0
    gain: float = 100.0


def default_dome(boards: int, leds_per_board: int, radius_m: float = 0.5) -> Dome:
    """LEDs on a hemisphere of ``radius_m``: board ``b`` is a ring at elevation
    ``15 + 60 b / boards`` degrees, its LEDs evenly spaced in azimuth (each ring offset by half a
    step so that the rings interleave)."""
    positions = np.zeros((boards, leds_per_board, 3))
    for b in range(boards):
        elevation = np.deg2rad(15.0 + 60.0 * b / boards)
        for i in range(leds_per_board):
            azimuth = 2.0 * np.pi * (i + 0.5 * (b % 2)) / leds_per_board
            positions[b, i] = radius_m * np.array([np.cos(elevation) * np.sin(azimuth),
                                                   np.sin(elevation),
                                                   np.cos(elevation) * np.cos(azimuth)])
    return Dome(positions)


def albedo_at(p_object: np.ndarray) -> np.ndarray:
    """Diffuse albedo (N, 3) at points on the sphere, in the object's frame: eight coloured
    longitude segments and a darker band round the equator, so that turning the table changes
    the image."""
    longitude = np.arctan2(p_object[:, 0], p_object[:, 2])
    segment = np.floor((longitude + np.pi) / (2.0 * np.pi) * 8.0).astype(int) % 8
    palette = np.array([[0.8, 0.2, 0.2], [0.8, 0.6, 0.2], [0.6, 0.8, 0.2], [0.2, 0.8, 0.3],
                        [0.2, 0.7, 0.8], [0.2, 0.3, 0.8], [0.6, 0.2, 0.8], [0.8, 0.8, 0.8]])
    band = np.abs(p_object[:, 1]) < 0.2 * SPHERE_RADIUS_M
    return palette[segment] * np.where(band, 0.4, 1.0)[:, None]


def render_frame(dome: Dome, width: int, height: int, angle_deg: float, global_level: int,
                 leds: dict[tuple[int, int], int], exposure_s: float) -> np.ndarray:
    """The image the simulated camera records.

    Parameters
    ----------
    dome : Dome
        Geometry and light powers.
    width, height : int
        Image size, pixels.
    angle_deg : float
        Turntable angle, degrees.
    global_level : int
        Global light level, 0..255.
    leds : dict of (int, int) to int
        Level (0..255) of every lit LED by (board, led).
    exposure_s : float
        Exposure time, seconds.

    Returns
    -------
    np.ndarray
        float32 (height, width, 3) in [0, 1]; 0 off the sphere (a black background).
    """
    K = intrinsics_from_fov(width, height, np.deg2rad(dome.fov_y_deg))
    R, t = look_at(dome.camera_eye, np.zeros(3))
    v, u = np.mgrid[0:height, 0:width]
    origins, dirs = ray_directions(K, R, t, np.stack([u.ravel(), v.ravel()], axis=-1).astype(float))
    # Ray-sphere intersection, |o + s d|^2 = r^2 with |d| = 1: the nearer root.
    b = np.sum(origins * dirs, axis=1)
    disc = b * b - (np.sum(origins * origins, axis=1) - SPHERE_RADIUS_M ** 2)
    hit = disc > 0
    s = -b - np.sqrt(np.where(hit, disc, 0.0))
    p = origins + s[:, None] * dirs
    n = p / SPHERE_RADIUS_M
    a = np.deg2rad(angle_deg)
    c, si = np.cos(a), np.sin(a)
    # The object turned by +a about y; a world point is at rotation(-a) of it in the object frame.
    rot_inv = np.array([[c, 0.0, -si], [0.0, 1.0, 0.0], [si, 0.0, c]])
    rho = albedo_at(p @ rot_inv.T)
    irradiance = np.full(p.shape[0], dome.global_irradiance * global_level / 255.0)
    for (board, led), level in leds.items():
        if level <= 0:
            continue
        q = dome.led_positions[board, led]
        to_light = q - p
        d2 = np.sum(to_light * to_light, axis=1)
        wi = to_light / np.sqrt(d2)[:, None]
        axis = -q / np.linalg.norm(q)
        # cos of the angle off the LED's axis, for its radial attenuation profile.
        off_axis = np.clip(np.sum(-wi * axis, axis=1), 0.0, 1.0)
        intensity = dome.led_intensity_w_sr * (level / 255.0) * off_axis ** dome.led_falloff_exponent
        # A convex sphere shadows itself exactly where n.wi < 0: no shadow rays needed.
        irradiance += intensity * np.clip(np.sum(n * wi, axis=1), 0.0, None) / d2
    radiance = rho / np.pi * irradiance[:, None]
    pixel = np.where(hit[:, None], radiance * exposure_s * dome.gain, 0.0)
    return np.clip(pixel, 0.0, 1.0).reshape(height, width, 3).astype(np.float32)
