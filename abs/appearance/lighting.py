"""The lighting term L_φ: what a white Lambertian surface with a pixel's normal would reflect.

For every object pixel, ``L = E(n) / π``, the cosine-weighted mean radiance of the environment
over the hemisphere around the normal ``n`` (the irradiance over π), from the map's order-2
spherical-harmonic projection (Ramamoorthi and Hanrahan 2001: 9 coefficients per channel,
accurate to a few per cent for any map, exact for one of order 2 or less, e.g. a constant one).
It ignores the box's walls (their shadowing and inter-reflection): those belong to the scene, are
the same for every renderer on the same design, and cancel in a transfer. A white Lambertian
sphere under a constant environment ``L0`` has radiance ``L0`` everywhere, and so ``L = L0``.

The map follows docs/conventions.md (Mitsuba's ``envmap``: ``u = atan2(x, -z) / 2π``,
``v = acos(y) / π``, row centres at ``v = j / (H - 1)``), with no rotation.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sh9_coefficients", "lighting_image"]

# Convolution of the clamped cosine with the SH bands 0, 1, 2 (Ramamoorthi and Hanrahan 2001).
_BAND_GAIN = np.array([np.pi] + [2.0 * np.pi / 3.0] * 3 + [np.pi / 4.0] * 5)


def _sh9(d: np.ndarray) -> np.ndarray:
    """Real spherical harmonics of bands 0-2 at unit directions ``(..., 3)``: ``(..., 9)``."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x,
                     1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1),
                     1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=-1)


def sh9_coefficients(environment: np.ndarray) -> np.ndarray:
    """``(9, 3)`` SH coefficients of a lat-long map ``(H, W, 3)`` (linear RGB radiance)."""
    h, w = environment.shape[:2]
    theta = np.pi * np.arange(h) / (h - 1)
    phi = 2.0 * np.pi * (np.arange(w) + 0.5) / w
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack(np.broadcast_arrays(st * np.sin(phi), ct, -st * np.cos(phi)), axis=-1)
    weight = np.broadcast_to(st, (h, w)).copy()
    weight[[0, -1]] *= 0.5  # the pole rows cover half a row each
    weight *= 4.0 * np.pi / weight.sum()  # solid angles summing to the whole sphere
    return np.einsum("hwk,hw,hwc->kc", _sh9(d), weight, np.asarray(environment, np.float64))


def lighting_image(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """``E(n) / π`` per pixel, ``(..., 3)``, from :func:`sh9_coefficients` and unit normals."""
    return np.maximum(np.einsum("...k,k,kc->...c", _sh9(normals), _BAND_GAIN, coefficients), 0.0) / np.pi
