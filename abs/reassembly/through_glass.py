"""Markers seen through glass: a camera ray that crosses a glass object before it reaches the
marker.

A marker seen through glass is displaced by refraction in that image, so its triangulated
position is wrong by an amount the stereo geometry cannot see (the displaced detections can still
lie on each other's epipolar lines). The check is geometric and simple: the segment from the
camera centre to the marker crosses the glass mesh (world frame, e.g. the CT mesh placed by a
first placement) more than ``margin_m`` before the marker. The margin keeps markers glued on the
near side, whose centre lies just outside the glass surface, from being flagged by a ray that
grazes the glass beside them.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["seen_through_glass"]


def seen_through_glass(points: np.ndarray, camera_centres: np.ndarray, glass: trimesh.Trimesh,
                       margin_m: float = 2e-3) -> np.ndarray:
    """Which camera sees which point through the glass.

    Parameters
    ----------
    points : (n, 3) array
        Marker positions, world frame, metres.
    camera_centres : (m, 3) array
        Camera centres, world frame, metres.
    glass : trimesh.Trimesh
        The glass object in the world frame, metres.
    margin_m : float
        A crossing counts only if it lies more than this before the point, metres.

    Returns
    -------
    (n, m) bool array
    """
    points = np.asarray(points, np.float64).reshape(-1, 3)
    centres = np.asarray(camera_centres, np.float64).reshape(-1, 3)
    out = np.zeros((len(points), len(centres)), bool)
    if len(points) == 0 or len(centres) == 0:
        return out
    triangles = np.asarray(glass.triangles, np.float64)
    for j, eye in enumerate(centres):
        for i, point in enumerate(points):
            out[i, j] = _crosses(eye, point, triangles, margin_m)
    return out


def _crosses(origin: np.ndarray, target: np.ndarray, triangles: np.ndarray, margin_m: float) -> bool:
    """Whether the segment from ``origin`` to ``target``, shortened by ``margin_m`` at the
    target end, crosses a triangle (Moller-Trumbore on all ``(k, 3, 3)`` triangles at once; in
    numpy because trimesh's ray casting needs rtree or embree, neither a dependency)."""
    length = np.linalg.norm(target - origin)
    if length <= margin_m:
        return False
    d = (target - origin) / length
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-15
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    dist = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0) & (dist < length - margin_m)
    return bool(hit.any())
