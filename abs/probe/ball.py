"""Where the ball is: its centre and radius from its outline in calibrated views.

A sphere's outline, seen from a pinhole camera at ``c``, is where the viewing cone with apex
``c`` touches it: every outline ray ``r`` (unit, world) makes the same angle ``α`` with the cone's
axis ``a``, the direction from ``c`` to the ball centre, so ``r · a = cos α``. Writing
``b = a / cos α`` this is linear, ``r · b = 1``, solved by least squares over the outline points;
then ``a = b/|b|`` and ``cos α = 1/|b|``. (The centre of the outline's ellipse in the image is
*not* the projection of the ball centre under perspective, which is why the cone is used.)

Two or more views triangulate the axes (the point closest to all axis lines, least squares);
the radius is ``|centre − c| sin α`` averaged over the views.
"""

from __future__ import annotations

import numpy as np

from abs.camera.pinhole import ray_directions
from abs.errors import InputError

__all__ = ["outline_cone", "triangulate_ball"]


def outline_cone(K, R, t, outline_px: np.ndarray, source: str | None = None) -> tuple[np.ndarray, float]:
    """Axis (unit, world) and half-angle [rad] of the cone from a camera to a ball's outline.

    Parameters
    ----------
    K, R, t : array-like
        The calibrated camera (docs/conventions.md).
    outline_px : ndarray, shape (N, 2)
        ``(u, v)`` pixels on the ball's outline, N >= 3, spread around it.
    source : str, optional
        Named in errors (the annotation file or view).
    """
    outline_px = np.asarray(outline_px, np.float64)
    if outline_px.ndim != 2 or outline_px.shape[0] < 3 or outline_px.shape[1] != 2:
        raise InputError(source, "outline", f"expected at least 3 (u, v) points, got shape {outline_px.shape}")
    _, rays = ray_directions(K, R, t, outline_px)
    b, *_ = np.linalg.lstsq(rays, np.ones(len(rays)), rcond=None)
    norm = float(np.linalg.norm(b))
    if norm <= 1.0:
        raise InputError(source, "outline", "the points do not lie on a circle-like outline "
                                            "(cone half-angle would exceed 90 degrees)")
    return b / norm, float(np.arccos(1.0 / norm))


def triangulate_ball(cameras: list[tuple], outlines: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """Ball centre (world, m) and radius (m) from its outline in two or more calibrated views.

    Parameters
    ----------
    cameras : list of (K, R, t)
    outlines : list of ndarray, shape (N_i, 2)
        Outline pixels per view, same order.
    """
    if len(cameras) < 2 or len(cameras) != len(outlines):
        raise InputError(None, "outline", "need the outline in at least two views, one per camera")
    centres, axes, angles = [], [], []
    for (K, R, t), outline in zip(cameras, outlines):
        axis, alpha = outline_cone(K, R, t, outline)
        centres.append(-np.asarray(R).T @ np.asarray(t).reshape(3))
        axes.append(axis)
        angles.append(alpha)
    # Point minimising the squared distances to the lines c_i + s a_i.
    A = sum(np.eye(3) - np.outer(a, a) for a in axes)
    rhs = sum((np.eye(3) - np.outer(a, a)) @ c for a, c in zip(axes, centres))
    centre = np.linalg.solve(A, rhs)
    radius = float(np.mean([np.linalg.norm(centre - c) * np.sin(al) for c, al in zip(centres, angles)]))
    return centre, radius
