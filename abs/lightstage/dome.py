"""A hemispherical LED dome around one camera, as a :class:`~abs.lightstage.geometry.RigGeometry`.

The layout of the thesis's low-cost dome and of the simulated rig (rig/sim/optics.py): LEDs on
rings of a hemisphere, each aimed at the turntable centre, one camera looking at the centre from
the front. Used by the benchmark and to describe simulated sessions.
"""

from __future__ import annotations

import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.lightstage.attenuation import Attenuation
from abs.lightstage.geometry import Camera, Led, RigGeometry

__all__ = ["led_name", "dome_geometry"]


def led_name(board: int, led: int) -> str:
    """The session's name of an LED (rig/plan.py): ``b01l07``."""
    return f"b{board:02d}l{led:02d}"


def dome_geometry(led_positions: np.ndarray, camera_eye: np.ndarray, fov_y_deg: float, width: int,
                  height: int, falloff_exponent: float = 4.0, intensity_w_sr: float = 1.0,
                  gain: float = 100.0) -> RigGeometry:
    """The geometry of a dome whose LEDs all aim at the origin (the turntable centre, axis +y).

    Parameters
    ----------
    led_positions : np.ndarray
        (boards, leds_per_board, 3) LED positions, metres.
    camera_eye : np.ndarray
        (3,) camera centre, metres; it looks at the origin with +y up.
    fov_y_deg : float
        Vertical field of view, degrees.
    width, height : int
        Image size, pixels.
    falloff_exponent : float
        Radial attenuation ``cos^m`` off each LED's axis.
    intensity_w_sr : float
        On-axis intensity of every LED at full level, W/sr per channel.
    gain : float
        Pixel value per unit radiance per second.
    """
    K = intrinsics_from_fov(width, height, np.deg2rad(fov_y_deg))
    R, t = look_at(np.asarray(camera_eye, np.float64), np.zeros(3))
    leds = {}
    for b in range(led_positions.shape[0]):
        for i in range(led_positions.shape[1]):
            q = np.asarray(led_positions[b, i], np.float64)
            leds[led_name(b, i)] = Led(q, -q / np.linalg.norm(q), np.full(3, intensity_w_sr))
    return RigGeometry((Camera(K, R, t, width, height),), leds, np.array([0.0, 1.0, 0.0]), np.zeros(3),
                       Attenuation(falloff_exponent), gain)
