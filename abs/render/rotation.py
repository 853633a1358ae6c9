"""Rotation matrices of rotation vectors in Dr.Jit, differentiable at zero (object poses, the
environment's orientation)."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["rotation_matrix"]


def rotation_matrix(r) -> mi.Matrix3f:
    """Rotation matrix of a rotation vector ``r`` (axis * angle, radians); differentiable at 0.

    Rodrigues' formula ``I + a K + b K^2`` (``K`` the cross-product matrix of ``r``), with the
    Taylor series of ``a = sin t / t`` and ``b = (1 - cos t) / t^2`` near ``t = 0``. At ``r = 0``
    it is the identity exactly (``K = 0``), so a rotation at its null value leaves whatever it
    multiplies bit for bit unchanged.
    """
    theta2 = dr.squared_norm(r)
    theta = dr.sqrt(theta2 + 1e-24)
    small = theta2 < 1e-8
    a = dr.select(small, 1.0 - theta2 / 6.0, dr.sin(theta) / theta)
    b = dr.select(small, 0.5 - theta2 / 24.0, (1.0 - dr.cos(theta)) / dr.square(theta))
    x, y, z = r.x, r.y, r.z
    k = mi.Matrix3f(0.0, -z, y, z, 0.0, -x, -y, x, 0.0)
    return mi.Matrix3f(1.0) + a * k + b * (k @ k)
