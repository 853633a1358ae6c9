"""Isotropic measurement normalisation: the angles of (n, l, v) that an isotropic BRDF depends on.

The thesis rotates every measurement's normal, light and eye vectors into one common orientation
so that measurements taken at different turntable angles, from different LEDs, line up. For an
isotropic BRDF that orientation is: the normal on +z and the light in the x-z plane. What is left
are three angles, ``(theta_l, theta_v, phi)`` (light and view elevation, azimuth between them), or
equivalently Rusinkiewicz's ``(theta_h, theta_d, phi_d)``; both are invariant under any rotation
of the three vectors together, which is what makes measurements from different poses comparable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Isotropic", "normalise"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


@dataclass(frozen=True)
class Isotropic:
    """Isotropic coordinates of N measurements (angles in radians).

    Attributes
    ----------
    light, view : np.ndarray
        (N, 3) unit light and view directions in the canonical frame (normal = +z, light in the
        x-z plane with x >= 0).
    theta_l, theta_v, phi : np.ndarray
        Light and view elevation from the normal, and the view's azimuth from the light's.
    theta_h, theta_d, phi_d : np.ndarray
        Rusinkiewicz's half-vector elevation, difference elevation and difference azimuth.
    """

    light: np.ndarray
    view: np.ndarray
    theta_l: np.ndarray
    theta_v: np.ndarray
    phi: np.ndarray
    theta_h: np.ndarray
    theta_d: np.ndarray
    phi_d: np.ndarray

    @property
    def cos_l(self) -> np.ndarray:
        return self.light[:, 2]

    @property
    def cos_v(self) -> np.ndarray:
        return self.view[:, 2]

    @property
    def cos_h(self) -> np.ndarray:
        return np.cos(self.theta_h)

    @property
    def cos_d(self) -> np.ndarray:
        return np.cos(self.theta_d)


def normalise(normal: np.ndarray, light: np.ndarray, view: np.ndarray) -> Isotropic:
    """Rotate (n, l, v) so that n = +z and l lies in the x-z plane; return the isotropic angles.

    Parameters
    ----------
    normal, light, view : np.ndarray
        (N, 3) directions (need not be unit): surface normal, towards the light, towards the eye.
    """
    n, l, v = _unit(normal), _unit(light), _unit(view)
    cos_l = np.clip(np.sum(n * l, 1), -1.0, 1.0)
    cos_v = np.clip(np.sum(n * v, 1), -1.0, 1.0)
    # Tangent x: the light's projection onto the tangent plane; at normal incidence any tangent
    # will do (the azimuth is then undefined), so fall back to one orthogonal to n.
    tx = l - cos_l[:, None] * n
    small = np.linalg.norm(tx, axis=1) < 1e-9
    if np.any(small):
        helper = np.where(np.abs(n[small, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        tx[small] = helper - np.sum(helper * n[small], 1, keepdims=True) * n[small]
    tx = _unit(tx)
    ty = np.cross(n, tx)
    canon_l = np.stack([np.sum(l * tx, 1), np.sum(l * ty, 1), cos_l], 1)
    canon_v = np.stack([np.sum(v * tx, 1), np.sum(v * ty, 1), cos_v], 1)
    theta_l = np.arccos(cos_l)
    theta_v = np.arccos(cos_v)
    phi = np.arctan2(canon_v[:, 1], canon_v[:, 0]) - np.arctan2(canon_l[:, 1], canon_l[:, 0])
    phi = np.mod(phi + np.pi, 2.0 * np.pi) - np.pi
    # Rusinkiewicz: half vector h; the difference vector is the light seen in a frame where h = z.
    h = _unit(canon_l + canon_v)
    theta_h = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    d = _rotate_z(canon_l, -phi_h)
    d = _rotate_y(d, -theta_h)
    theta_d = np.arccos(np.clip(d[:, 2], -1.0, 1.0))
    phi_d = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi)
    return Isotropic(canon_l, canon_v, theta_l, theta_v, phi, theta_h, theta_d, phi_d)


def _rotate_z(v: np.ndarray, a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], 1)


def _rotate_y(v: np.ndarray, a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * v[:, 0] + s * v[:, 2], v[:, 1], -s * v[:, 0] + c * v[:, 2]], 1)
