"""A closed mesh from the object's silhouette: the mask inflated into a round solid.

One photograph fixes the object's outline but not its depth. The analysis-by-synthesis edit
(:mod:`abs.resynthesis.method`) starts from the roundest solid with that outline: every point of
the mask is lifted towards the camera by a circular profile of its distance ``d`` to the outline,
``h = sqrt(d (2 R - d))`` with ``R`` the largest distance (the inradius), and mirrored away from
the camera. For a disc this is exactly a sphere of the disc's radius; for other outlines it is
the usual "inflation" of sketch-based modelling (Igarashi et al. 1999). The front and back sheets
share the outline's vertices, so the mesh is closed (glass needs an inside).

Geometry (docs/conventions.md): pixel corners are lifted along their camera rays, so the mesh's
outline projects exactly onto the mask's outline; lengths are metres, depth ``h`` is converted
from pixels at the object's distance (``h_m = h_px distance / f``).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["inflation_heights", "inflated_mesh"]


def inflation_heights(mask: np.ndarray) -> np.ndarray:
    """Heights of the pixel corners above the silhouette's plane, pixels.

    Parameters
    ----------
    mask : np.ndarray
        ``(height, width)`` bool, the object.

    Returns
    -------
    np.ndarray
        ``(height + 1, width + 1)`` heights at the pixel corners (corner ``(j, i)`` is the top-left
        corner of pixel ``(j, i)``); 0 on the outline and outside, ``sqrt(d (2R - d))`` inside.
    """
    m = np.pad(np.asarray(mask, bool), 1)
    # A corner is inside when all four pixels around it are in the mask.
    inside = m[:-1, :-1] & m[:-1, 1:] & m[1:, :-1] & m[1:, 1:]
    # Distance from an inside corner to the nearest outline corner (corner spacing = 1 pixel).
    d = ndimage.distance_transform_edt(inside)
    radius = float(d.max())
    if radius <= 0:
        return np.zeros(inside.shape)
    return np.sqrt(np.clip(d * (2.0 * radius - d), 0.0, None))


def inflated_mesh(mask: np.ndarray, K: np.ndarray, distance: float,
                  relief: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The inflated silhouette as a closed triangle mesh in the camera frame.

    Parameters
    ----------
    mask : np.ndarray
        ``(height, width)`` bool, the object (not touching the border).
    K : np.ndarray
        ``(3, 3)`` intrinsics of the photograph, pixels.
    distance : float
        Depth of the silhouette's plane along the optical axis, metres.
    relief : float
        Multiplier of the heights (1: round; a sphere for a disc).

    Returns
    -------
    vertices : np.ndarray
        ``(n, 3)`` float64, camera frame (x right, y down, z forward), metres.
    faces : np.ndarray
        ``(m, 3)`` int64, counter-clockwise seen from outside (normals point out).
    """
    h_px = inflation_heights(mask) * relief
    rows, cols = h_px.shape
    # Corner (j, i) sits at pixel coordinates (i - 0.5, j - 0.5).
    u, v = np.meshgrid(np.arange(cols) - 0.5, np.arange(rows) - 0.5)
    rays = np.linalg.solve(K, np.stack([u.ravel(), v.ravel(), np.ones(u.size)]))  # z = 1
    focal = float(np.sqrt(K[0, 0] * K[1, 1]))
    h_m = h_px.ravel() * distance / focal
    pm = np.asarray(mask, bool)
    used = np.zeros((rows, cols), bool)
    used[:-1, :-1] |= pm
    used[:-1, 1:] |= pm
    used[1:, :-1] |= pm
    used[1:, 1:] |= pm
    outline = used & (h_px <= 0)
    index = np.full(rows * cols, -1)
    front = np.flatnonzero(used)
    index[front] = np.arange(front.size)
    back_only = np.flatnonzero(used & ~outline)
    back_index = index.copy()
    back_index[back_only] = front.size + np.arange(back_only.size)  # outline: shared vertices
    verts_front = (rays[:, front] * (distance - h_m[front])).T
    verts_back = (rays[:, back_only] * (distance + h_m[back_only])).T
    jj, ii = np.nonzero(pm)
    a, b = jj * cols + ii, jj * cols + ii + 1  # top-left, top-right corners
    c, d = a + cols, b + cols                  # bottom-left, bottom-right
    # Seen from the camera (outside the front sheet), x right and y down is clockwise on screen
    # for (a, b, d): so (a, d, b) and (a, c, d) face the camera.
    f = np.concatenate([np.stack([index[a], index[d], index[b]], 1),
                        np.stack([index[a], index[c], index[d]], 1)])
    k = np.concatenate([np.stack([back_index[a], back_index[b], back_index[d]], 1),
                        np.stack([back_index[a], back_index[d], back_index[c]], 1)])
    faces = np.concatenate([f, k]).astype(np.int64)
    return np.concatenate([verts_front, verts_back]), faces
