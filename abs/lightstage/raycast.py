"""Rays against the object's mesh with Mitsuba: first hits of camera rays and shadow rays to LEDs.

Mitsuba's BVH (through Dr.Jit, the variant abs selects) intersects millions of rays in one
vectorised call, where trimesh's pure-Python ray casting (without Embree) would take minutes for a
session. Rays are traced in the object's frame, so one static scene serves every turntable angle:
the camera rays and LED positions are moved into the object's frame instead of moving the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Hits", "MeshTracer"]


@dataclass(frozen=True)
class Hits:
    """First hits of a batch of rays.

    Attributes
    ----------
    valid : np.ndarray
        (N,) bool, the ray hit the mesh.
    triangle : np.ndarray
        (N,) int, hit triangle (-1 where no hit).
    barycentric : np.ndarray
        (N, 2) float, barycentric weights ``(b1, b2)`` of the triangle's vertices 1 and 2.
    point : np.ndarray
        (N, 3) hit points, metres (object frame).
    normal : np.ndarray
        (N, 3) unit shading normals (vertex normals interpolated), facing the ray's origin side.
    """

    valid: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    point: np.ndarray
    normal: np.ndarray


class MeshTracer:
    """A triangle mesh in a Mitsuba scene, for batched ray queries in numpy.

    Parameters
    ----------
    vertices : np.ndarray
        (V, 3) vertex positions, metres.
    faces : np.ndarray
        (F, 3) vertex indices, counter-clockwise seen from outside.
    vertex_normals : np.ndarray, optional
        (V, 3) unit vertex normals for smooth shading; face normals when omitted.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray,
                 vertex_normals: np.ndarray | None = None):
        import mitsuba as mi

        from abs.render.variant import current_variant, set_variant

        if current_variant() is None:
            set_variant(None)
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.vertex_normals = None if vertex_normals is None else np.asarray(vertex_normals, np.float64)
        mesh = mi.Mesh("lightstage", vertex_count=len(self.vertices), face_count=len(self.faces),
                       has_vertex_normals=False, has_vertex_texcoords=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(self.vertices.astype(np.float32).ravel())
        params["faces"] = mi.UInt32(self.faces.astype(np.uint32).ravel())
        params.update()
        self._mi = mi
        self.scene = mi.load_dict({"type": "scene", "object": mesh})
        e1 = self.vertices[self.faces[:, 1]] - self.vertices[self.faces[:, 0]]
        e2 = self.vertices[self.faces[:, 2]] - self.vertices[self.faces[:, 0]]
        n = np.cross(e1, e2)
        self.face_normals = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)

    def _rays(self, origins: np.ndarray, dirs: np.ndarray, maxt: np.ndarray | None = None):
        mi = self._mi
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(dirs, dtype=np.float32)
        ray = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
        if maxt is not None:
            ray.maxt = mi.Float(np.ascontiguousarray(maxt, dtype=np.float32))
        return ray

    def intersect(self, origins: np.ndarray, dirs: np.ndarray) -> Hits:
        """First hits of rays ``origins + s dirs`` (both (N, 3), dirs unit, object frame)."""
        n_rays = len(origins)
        if n_rays == 0:
            z = np.zeros((0, 3))
            return Hits(np.zeros(0, bool), np.zeros(0, np.int64), np.zeros((0, 2)), z, z)
        si = self.scene.ray_intersect(self._rays(origins, dirs))
        valid = np.asarray(si.is_valid(), dtype=bool)
        tri = np.where(valid, np.asarray(si.prim_index, dtype=np.int64), -1)
        dist = np.asarray(si.t, dtype=np.float64)
        point = np.where(valid[:, None], origins + np.where(valid, dist, 0.0)[:, None] * dirs, 0.0)
        # Barycentrics recomputed in float64 from the hit point: independent of how Mitsuba fills
        # ``si.uv`` for a mesh without texture coordinates.
        bary = np.zeros((n_rays, 2))
        normal = np.zeros((n_rays, 3))
        idx = np.nonzero(valid)[0]
        if idx.size:
            f = self.faces[tri[idx]]
            a, b, c = (self.vertices[f[:, k]] for k in range(3))
            bary[idx] = _barycentric(point[idx], a, b, c)
            normal[idx] = self.shading_normal(tri[idx], bary[idx])
            # Shade the side the ray came from (a closed mesh is hit from outside).
            flip = np.sum(normal[idx] * dirs[idx], axis=1) > 0
            normal[idx[flip]] *= -1.0
        return Hits(valid, tri, bary, point, normal)

    def shading_normal(self, triangle: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
        """Unit normals (N, 3) at barycentrics ``(b1, b2)`` of ``triangle``."""
        if self.vertex_normals is None:
            return self.face_normals[triangle]
        f = self.faces[triangle]
        b1, b2 = barycentric[:, :1], barycentric[:, 1:2]
        n = ((1.0 - b1 - b2) * self.vertex_normals[f[:, 0]] + b1 * self.vertex_normals[f[:, 1]]
             + b2 * self.vertex_normals[f[:, 2]])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)

    def visible(self, points: np.ndarray, normals: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """(N,) bool: nothing of the mesh lies between each surface point and its target.

        The shadow ray starts a small offset along the geometric side of the normal, so the
        surface it leaves does not shadow it; the offset scales with the mesh's size.
        """
        if len(points) == 0:
            return np.zeros(0, bool)
        eps = 1e-4 * float(np.ptp(self.vertices, axis=0).max())
        to = targets - points
        dist = np.linalg.norm(to, axis=1)
        d = to / np.maximum(dist, 1e-30)[:, None]
        start = points + eps * normals
        blocked = np.asarray(self.scene.ray_test(self._rays(start, d, dist * (1.0 - 1e-4) - eps)),
                             dtype=bool)
        return ~blocked


def _barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``(b1, b2)`` of points ``p`` in triangles ``(a, b, c)``, clipped into the triangle."""
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.sum(v0 * v0, 1)
    d01 = np.sum(v0 * v1, 1)
    d11 = np.sum(v1 * v1, 1)
    d20 = np.sum(v2 * v0, 1)
    d21 = np.sum(v2 * v1, 1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-300)
    b1 = np.clip((d11 * d20 - d01 * d21) / den, 0.0, 1.0)
    b2 = np.clip((d00 * d21 - d01 * d20) / den, 0.0, 1.0)
    s = b1 + b2
    over = s > 1.0
    b1 = np.where(over, b1 / s, b1)
    b2 = np.where(over, b2 / s, b2)
    return np.stack([b1, b2], axis=1)
