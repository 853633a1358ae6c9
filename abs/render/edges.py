"""Visibility gradients of moving objects by silhouette edge sampling (Li et al. 2018,
"Differentiable Monte Carlo ray tracing through edge sampling").

When a parameter moves an object (``<object>.pose``), its silhouette sweeps across the image and
the pixel integrals gain a boundary term that automatic differentiation of the (continuous)
interior misses. For a pixel filter ``k`` the term is

    d/dtheta I_p = integral over silhouette edges of k(x - p) (L_minus - L_plus) (dx/dtheta . n) dl

with ``n`` the edge's unit normal in the image and ``L_plus``, ``L_minus`` the radiance just on
either side. We sample points on the projected silhouette edges in proportion to their length,
estimate both radiances with the path tracer (detached), and attach the edge point's image
position to the parameters through the mesh's attached vertex positions. The returned image is
zero in value and carries exactly the boundary term in its derivative.

Silhouette edges are mesh edges whose two faces face opposite ways as seen from the camera
centre, plus boundary edges of open meshes. Only primary visibility is handled this way: shadow
and reflected/refracted silhouettes are not (see docs/renderer.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

__all__ = ["MovingMesh", "edge_adjacency", "silhouette_edges", "boundary_term"]

# Offset of the two radiance probes from the edge, in pixels: small against a pixel, but outside
# the sliver next to a polygonal silhouette where interpolated shading normals face away from the
# camera and shading turns black (measured: 0.001 px probes see it, 0.02 px ones do not).
_PROBE_OFFSET_PX = 0.02


@dataclass(frozen=True)
class MovingMesh:
    """A mesh whose vertices depend on differentiated parameters.

    Attributes
    ----------
    positions : mi.Float
        Flat ``x, y, z`` vertex positions, attached to the AD graph.
    edges : ndarray, shape (E, 2)
        Unique undirected edges (vertex indices).
    edge_faces : ndarray, shape (E, 2)
        The faces on either side of each edge (-1 for a boundary edge).
    faces : ndarray, shape (F, 3)
    """

    positions: mi.Float
    edges: np.ndarray
    edge_faces: np.ndarray
    faces: np.ndarray


def edge_adjacency(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges of a triangle mesh and the (up to two) faces adjacent to each."""
    faces = np.asarray(faces, np.int64)
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    face_of = np.tile(np.arange(len(faces)), 3)
    key = np.sort(pairs, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, face_of = key[order], face_of[order]
    unique, start, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    edge_faces = np.full((len(unique), 2), -1, np.int64)
    edge_faces[:, 0] = face_of[start]
    two = counts >= 2
    edge_faces[two, 1] = face_of[start[two] + 1]
    return unique, edge_faces


def silhouette_edges(vertices: np.ndarray, mesh: MovingMesh, eye: np.ndarray) -> np.ndarray:
    """Indices (into ``mesh.edges``) of the silhouette edges seen from ``eye``."""
    tri = vertices[mesh.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    front = np.einsum("ij,ij->i", normals, eye - tri[:, 0]) > 0
    f0, f1 = mesh.edge_faces[:, 0], mesh.edge_faces[:, 1]
    boundary = f1 < 0
    differ = np.zeros(len(f0), bool)
    differ[~boundary] = front[f0[~boundary]] != front[f1[~boundary]]
    return np.nonzero(differ | boundary)[0]


def boundary_term(tracer, scene, env, camera, meshes: list[MovingMesh], n_samples: int,
                  seed: int, channel: int) -> mi.TensorXf:
    """The silhouette boundary term of the image derivative (zero-valued, attached)."""
    w, h = camera.width, camera.height
    K, R, t = camera.K, camera.R, camera.t
    eye = camera.center
    starts, ends, owners, edge_ids = [], [], [], []
    for m, mesh in enumerate(meshes):
        vertices = np.array(dr.detach(mesh.positions), np.float64).reshape(-1, 3)
        sil = silhouette_edges(vertices, mesh, eye)
        cam = (R @ vertices.T).T + t
        ok = cam[:, 2] > 1e-6
        pix = (K @ cam.T).T
        pix = pix[:, :2] / np.where(ok, pix[:, 2], 1.0)[:, None]
        e = mesh.edges[sil]
        keep = ok[e[:, 0]] & ok[e[:, 1]]
        starts.append(pix[e[keep, 0]])
        ends.append(pix[e[keep, 1]])
        owners.append(np.full(int(keep.sum()), m))
        edge_ids.append(sil[keep])
    a, b = np.concatenate(starts), np.concatenate(ends)
    lengths = np.linalg.norm(b - a, axis=1)
    flat = dr.zeros(mi.Float, w * h * 3)
    total = float(lengths.sum())
    if total <= 0:
        return mi.TensorXf(flat, (h, w, 3))
    owner, edge_id = np.concatenate(owners), np.concatenate(edge_ids)

    rng = np.random.default_rng(seed)
    pick = rng.choice(len(lengths), size=n_samples, p=lengths / total)
    s = rng.uniform(size=n_samples)
    direction = (b - a)[pick] / lengths[pick, None]
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    x = a[pick] + s[:, None] * (b - a)[pick]

    # Attached image position of each edge point: project the attached edge end points.
    xs = []
    for m, mesh in enumerate(meshes):
        sel = owner[pick] == m
        verts = mesh.edges[edge_id[pick][sel]]
        p = mesh.positions

        def vertex(idx):
            idx = mi.UInt32(idx.astype(np.uint32))
            return mi.Vector3f(dr.gather(mi.Float, p, idx * 3), dr.gather(mi.Float, p, idx * 3 + 1),
                               dr.gather(mi.Float, p, idx * 3 + 2))

        pa, pb = vertex(verts[:, 0]), vertex(verts[:, 1])
        ss = mi.Float(s[sel].astype(np.float32))
        xs.append((np.nonzero(sel)[0], _project(camera, pa), _project(camera, pb), ss))
    # Reassemble in sample order.
    order = np.concatenate([i for i, *_ in xs])
    inverse = np.empty_like(order)
    inverse[order] = np.arange(len(order))
    xa = [dr.concat([q[1][k] for q in xs]) if len(xs) > 1 else xs[0][1][k] for k in range(2)]
    xb = [dr.concat([q[2][k] for q in xs]) if len(xs) > 1 else xs[0][2][k] for k in range(2)]
    ss = dr.concat([q[3] for q in xs]) if len(xs) > 1 else xs[0][3]
    inv = mi.UInt32(inverse.astype(np.uint32))
    xa = [dr.gather(mi.Float, c, inv) for c in xa]
    xb = [dr.gather(mi.Float, c, inv) for c in xb]
    ss = dr.gather(mi.Float, ss, inv)
    px = xa[0] + ss * (xb[0] - xa[0])
    py = xa[1] + ss * (xb[1] - xa[1])
    nx, ny = (mi.Float(normal[:, i].astype(np.float32)) for i in range(2))
    velocity = (px - dr.detach(px)) * nx + (py - dr.detach(py)) * ny  # zero value, attached

    # Radiance just on either side of the edge (detached).
    with dr.suspend_grad():
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, n_samples)
        radiance = []
        for sign in (1.0, -1.0):
            u = mi.Float((x[:, 0] + sign * _PROBE_OFFSET_PX * normal[:, 0]).astype(np.float32))
            v = mi.Float((x[:, 1] + sign * _PROBE_OFFSET_PX * normal[:, 1]).astype(np.float32))
            origin, d = camera.rays(u, v)
            ray = mi.Ray3f(origin, d, float(channel), mi.Color0f())
            radiance.append(tracer._trace(scene, env, ray, sampler))
        difference = radiance[1] - radiance[0]
    contribution = difference * velocity * (total / n_samples)

    # Splat through the tent pixel filter (the same filter the renderer integrates with).
    fx, fy = np.floor(x[:, 0]), np.floor(x[:, 1])
    for dx in (0, 1):
        for dy in (0, 1):
            cx, cy = fx + dx, fy + dy
            k = np.maximum(1 - np.abs(x[:, 0] - cx), 0) * np.maximum(1 - np.abs(x[:, 1] - cy), 0)
            inside = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h) & (k > 0)
            index = mi.UInt32(np.where(inside, (cy * w + cx) * 3, 0).astype(np.uint32))
            weight = mi.Float(np.where(inside, k, 0).astype(np.float32))
            for c, value in enumerate((contribution.x, contribution.y, contribution.z)):
                dr.scatter_add(flat, value * weight, index + c, mi.Bool(inside))
    return mi.TensorXf(flat, (h, w, 3))


def _project(camera, p: mi.Vector3f) -> tuple[mi.Float, mi.Float]:
    _, _, k, r = camera._mats()
    t = mi.Vector3f(*[float(v) for v in camera.t])
    q = k @ (r @ p + t)
    return q.x / q.z, q.y / q.z
