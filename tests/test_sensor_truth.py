"""Benchmark truths of sensor effects differ from abs's models but are close to what they can fit:
cos^4 vignetting is the polynomial to first order; glare preserves energy; the response saturates."""

from __future__ import annotations

import numpy as np

from abs.camera.pinhole import intrinsics_from_fov
from abs.render.camera import Camera
from abs.render.sensor_truth import filmic_response, natural_vignetting, veiling_glare


def test_natural_vignetting_first_order_and_centre():
    camera = Camera(intrinsics_from_fov(40, 30, np.radians(40)), np.eye(3), np.zeros(3), 40, 30)
    out = natural_vignetting(np.ones((30, 40, 3), np.float32), camera, strength=0.3)
    v, u = np.mgrid[0:30, 0:40]
    r2 = ((u - camera.K[0, 2]) ** 2 + (v - camera.K[1, 2]) ** 2) / camera.K[0, 0] ** 2
    np.testing.assert_allclose(out[..., 0], 1 / (1 + 0.09 * r2) ** 2, rtol=1e-5)
    # first order: 1 - 2 s^2 r^2 (abs's k1 = -2 s^2), off by O(r^4) only
    assert np.abs(out[..., 0] - (1 - 0.18 * r2)).max() < 3 * 0.0081 * r2.max() ** 2


def test_glare_adds_its_fraction_of_energy():
    rng = np.random.default_rng(0)
    image = rng.uniform(0, 1, (30, 40, 3)).astype(np.float32)
    out = veiling_glare(image, 0.05, 8.0, floor=[0.01, 0.0, 0.0])
    np.testing.assert_allclose(out.mean(axis=(0, 1)), image.mean(axis=(0, 1)) * 1.05 + [0.01, 0, 0],
                               rtol=2e-3)


def test_filmic_response_is_not_a_power_law():
    x = np.array([0.0, 0.05, 0.5, 2.0, 4.0])
    y = filmic_response(x)
    np.testing.assert_allclose(y, [0, 0.05 * 1.0125 / 1.05, 0.5 * 1.125 / 1.5, 1.0, 1.6], rtol=1e-6)
    slope = np.diff(np.log(y[[1, 2, 4]])) / np.diff(np.log(x[[1, 2, 4]]))
    assert np.ptp(slope) > 0.1  # log-log slope varies: no single gamma fits it
