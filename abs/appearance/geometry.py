"""Per-pixel normals, θ and material ids of a design scene, from its analytic geometry.

Why not from the renderer: Mitsuba's ``shape_index`` is not a stable object index (it follows
the order the scene was built in, and a second renderer may build it in another order), and a
renderer's normals carry its own tessellation and shading-normal choices. Spheres have exact
normals, so θ, the angle between the surface normal and the direction back to the camera, is
computed here from the camera ray and the sphere, independently of every renderer.

A pixel counts as a sphere's only when the whole footprint of abs's pixel filter (a tent of
radius one pixel, :mod:`abs.render.integrator`) lies on that sphere: rays through the pixel centre
and the four corners of the ±1-pixel square must all hit it first. Silhouette pixels, which mix
the sphere with what lies behind it, get id 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.camera.pinhole import ray_directions

__all__ = ["Geometry", "sphere_geometry"]


@dataclass(frozen=True)
class Geometry:
    """What the transfer needs to know of an image's pixels.

    Attributes
    ----------
    theta : np.ndarray
        ``(height, width)`` float32, radians in [0, π/2]: angle between the normal and the
        direction to the camera; NaN where ``ids == 0``.
    ids : np.ndarray
        ``(height, width)`` int32 material ids (0: background or silhouette).
    classes : tuple of str
        ``classes[id - 1]`` is the material class of id ``id``.
    normals : np.ndarray
        ``(height, width, 3)`` float32 unit world-space normals; 0 where ``ids == 0``.
    """

    theta: np.ndarray
    ids: np.ndarray
    classes: tuple[str, ...]
    normals: np.ndarray

    def class_mask(self, material_class: str) -> np.ndarray:
        """Pixels of every object of ``material_class``."""
        hits = [i + 1 for i, c in enumerate(self.classes) if c == material_class]
        return np.isin(self.ids, hits)


def _first_hit(origins: np.ndarray, dirs: np.ndarray, spheres: np.ndarray):
    """Index of the first sphere each ray hits (-1: none) and the hit distance (metres)."""
    best = np.full(dirs.shape[0], np.inf)
    index = np.full(dirs.shape[0], -1)
    for i, (cx, cy, cz, r) in enumerate(spheres):
        oc = origins - np.array([cx, cy, cz])
        b = np.einsum("ij,ij->i", oc, dirs)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        hit = (disc > 0) & (t > 0) & (t < best)
        best = np.where(hit, t, best)
        index = np.where(hit, i, index)
    return index, best


def sphere_geometry(K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int,
                    spheres: np.ndarray, classes: tuple[str, ...]) -> Geometry:
    """θ and ids of a pinhole view of spheres (nothing else may stand in front of them).

    Parameters
    ----------
    K, R, t : np.ndarray
        The camera (docs/conventions.md: ``x_cam = R X + t``, pixels).
    width, height : int
        Image size, pixels.
    spheres : np.ndarray
        ``(n, 4)``: centre (x, y, z) and radius per sphere, metres.
    classes : tuple of str
        Material class of each sphere.
    """
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    centre_uv = np.stack([u.ravel(), v.ravel()], axis=1)
    origins, dirs = ray_directions(K, R, t, centre_uv)
    index, dist = _first_hit(origins, dirs, spheres)
    pure = index >= 0
    for du, dv in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        o, d = ray_directions(K, R, t, centre_uv + np.array([du, dv], float))
        pure &= _first_hit(o, d, spheres)[0] == index
    ids = np.where(pure, index + 1, 0)
    safe = np.where(pure, index, 0)
    points = origins + dirs * np.where(pure, dist, 0.0)[:, None]
    normals = (points - spheres[safe, :3]) / spheres[safe, 3:4]
    cos_theta = np.clip(-np.einsum("ij,ij->i", normals, dirs), 0.0, 1.0)
    theta = np.where(pure, np.arccos(cos_theta), np.nan)
    normals = np.where(pure[:, None], normals, 0.0)
    return Geometry(theta.reshape(height, width).astype(np.float32),
                    ids.reshape(height, width).astype(np.int32), tuple(classes),
                    normals.reshape(height, width, 3).astype(np.float32))
