"""Visibility gradients of moving objects by silhouette edge sampling (Li et al. 2018,
"Differentiable Monte Carlo ray tracing through edge sampling").

When a parameter moves an object (``<object>.pose``, ``<object>.placement``), its silhouette sweeps
across the image and the pixel integrals gain a boundary term that automatic differentiation of
the (continuous) interior misses. For a pixel filter ``k`` the term is

    d/dtheta I_p = integral over silhouette edges of k(x - p) (L_minus - L_plus) (dx/dtheta . n) dl

with ``n`` the edge's unit normal in the image (for a camera with a footprint, ``k`` is a
sensor site's square, then the build's weights: :mod:`abs.render.footprint`) and ``L_plus``,
``L_minus`` the radiance just on either side. We sample points on the projected silhouette edges in proportion to their length,
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

from abs.camera.pinhole import project
from abs.render.jit import from_numpy, opaque, seed32

__all__ = ["MovingMesh", "edge_adjacency", "neighbour_mean", "silhouette_edges", "boundary_term"]

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


def neighbour_mean(values: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per vertex, the mean of ``values`` (shape ``(vertices, k)``) over the vertices it shares an
    edge with (its own value for a vertex on no face)."""
    edges, _ = edge_adjacency(faces)
    values = np.asarray(values, np.float64)
    total = np.zeros_like(values)
    count = np.zeros(len(values))
    for a, b in ((0, 1), (1, 0)):
        np.add.at(total, edges[:, a], values[edges[:, b]])
        np.add.at(count, edges[:, a], 1.0)
    alone = count == 0
    total[alone], count[alone] = values[alone], 1.0
    return total / count[:, None]


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
                  seed: int, split: bool) -> mi.TensorXf:
    """The silhouette boundary term of the image derivative (zero-valued, attached).

    ``split``: whether paths split by colour channel at dispersive glass, as in the interior render.
    """
    w, h = camera.width, camera.height
    flat = dr.zeros(mi.Float, w * h * 3)
    # All moving meshes as one vertex array, with edges as global vertex indices.
    pixels, edges, offset = [], [], 0
    for mesh in meshes:
        vertices = np.array(dr.detach(mesh.positions), np.float64).reshape(-1, 3)
        pix = project(camera.K, camera.R, camera.t, vertices)  # NaN behind the camera
        e = mesh.edges[silhouette_edges(vertices, mesh, camera.center)]
        in_front = np.isfinite(pix[e]).all(axis=(1, 2))
        pixels.append(pix)
        edges.append(e[in_front] + offset)
        offset += len(vertices)
    pix, edges = np.concatenate(pixels), np.concatenate(edges)
    a, b = pix[edges[:, 0]], pix[edges[:, 1]]
    lengths = np.linalg.norm(b - a, axis=1)
    total = float(lengths.sum())
    if total <= 0:
        return mi.TensorXf(flat, (h, w, 3))

    rng = np.random.default_rng(seed)
    pick = rng.choice(len(lengths), size=n_samples, p=lengths / total)
    s = rng.uniform(size=n_samples)
    direction = (b - a)[pick] / lengths[pick, None]
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    x = a[pick] + s[:, None] * (b - a)[pick]

    # Attached image position of each edge point, through the attached end points.
    positions = dr.concat([m.positions for m in meshes]) if len(meshes) > 1 else meshes[0].positions

    def vertex(index: np.ndarray) -> mi.Vector3f:
        i = from_numpy(mi.UInt32, index, np.uint32) * 3
        return mi.Vector3f(*[dr.gather(mi.Float, positions, i + k) for k in range(3)])

    ua, va = camera.project(vertex(edges[pick, 0]))
    ub, vb = camera.project(vertex(edges[pick, 1]))
    ss = from_numpy(mi.Float, s)
    px, py = ua + ss * (ub - ua), va + ss * (vb - va)
    nx, ny = (from_numpy(mi.Float, normal[:, i]) for i in range(2))
    velocity = (px - dr.detach(px)) * nx + (py - dr.detach(py)) * ny  # zero value, attached

    # Radiance just on either side of the edge (detached).
    with dr.suspend_grad():
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed32(seed), n_samples)
        radiance = []
        for sign in (1.0, -1.0):
            u = from_numpy(mi.Float, x[:, 0] + sign * _PROBE_OFFSET_PX * normal[:, 0])
            v = from_numpy(mi.Float, x[:, 1] + sign * _PROBE_OFFSET_PX * normal[:, 1])
            origin, d = camera.rays(u, v)
            ray = mi.Ray3f(origin, d, 3.0, mi.Color0f())  # time 3: no colour channel chosen yet
            radiance.append(tracer.trace(scene, env, ray, sampler, split)[0])
        difference = radiance[1] - radiance[0]
    # Opaque: the silhouette's length changes with the pose and must not become a kernel literal.
    contribution = difference * velocity * opaque(mi.Float, total / n_samples)

    if camera.footprint is not None:
        # Into the sensor site whose square holds the edge point (a site's value is its square's
        # mean), then to pixels with the build's weights (abs.render.footprint).
        film = camera.film()
        site, inverse_area = film.sites_at(x, rng)
        inside = site >= 0
        index = from_numpy(mi.UInt32, np.where(inside, site, 0), np.uint32)
        weight = from_numpy(mi.Float, inverse_area)
        inside_mask = from_numpy(mi.Bool, inside, np.bool_)
        values = []
        for value in (contribution.x, contribution.y, contribution.z):
            sites = dr.zeros(mi.Float, film.sites)
            dr.scatter_add(sites, value * weight, index, inside_mask)
            values.append(sites)
        return film.image(values, w, h)
    # Splat through the tent pixel filter (the same filter the renderer integrates with).
    fx, fy = np.floor(x[:, 0]), np.floor(x[:, 1])
    for dx in (0, 1):
        for dy in (0, 1):
            cx, cy = fx + dx, fy + dy
            k = np.maximum(1 - np.abs(x[:, 0] - cx), 0) * np.maximum(1 - np.abs(x[:, 1] - cy), 0)
            inside = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h) & (k > 0)
            index = from_numpy(mi.UInt32, np.where(inside, (cy * w + cx) * 3, 0), np.uint32)
            weight = from_numpy(mi.Float, np.where(inside, k, 0))
            inside_mask = from_numpy(mi.Bool, inside, np.bool_)
            for c, value in enumerate((contribution.x, contribution.y, contribution.z)):
                dr.scatter_add(flat, value * weight, index + c, inside_mask)
    return mi.TensorXf(flat, (h, w, 3))

