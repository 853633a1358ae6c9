"""Mesh cleaning for the CT glass mesh: carve the markers out, keep the largest piece, close the
holes, decimate (quadric edge collapse) and √3-subdivide.

Quadric decimation is Fast-Quadric-Mesh-Simplification through the ``fast-simplification``
package (trimesh's own ``simplify_quadric_decimation`` backend); a closed mesh it would open (the
two sides of a thin wall collapsed together) is decimated less. √3 subdivision (Kobbelt 2000)
is not offered by trimesh (midpoint and Loop only) nor by the other installed libraries, so it is
written here in numpy: one centroid per face, old vertices relaxed with
``alpha_n = (4 - 2 cos(2 pi / n)) / 9``, then every old edge flipped. Faces touching a boundary
are split 1-to-3 but not flipped, and boundary vertices are not moved.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["carve_spheres", "largest_component", "fill_holes", "boundary_loops", "decimate", "repair_closed",
           "sqrt3_subdivide", "subdivide_decimate"]


def carve_spheres(mesh: trimesh.Trimesh, centres: np.ndarray, radii: np.ndarray,
                  epsilon: float = 0.5) -> trimesh.Trimesh:
    """Remove the faces whose centroid lies within ``(1 + epsilon) * r_i`` of a centre ``c_i``."""
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    keep = np.ones(len(mesh.faces), dtype=bool)
    tc = mesh.triangles_center
    for c, r in zip(centres, radii):
        keep &= np.linalg.norm(tc - c, axis=1) > (1 + epsilon) * r
    out = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False)
    out.remove_unreferenced_vertices()
    return out


def largest_component(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The connected piece with most faces (streak debris and specks dropped)."""
    parts = mesh.split(only_watertight=False)
    if len(parts) <= 1:
        return mesh
    return max(parts, key=lambda m: len(m.faces))


def _directed_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    return edges, np.repeat(np.arange(len(faces)), 3)


def _twins(edges: np.ndarray, n_vertices: int) -> np.ndarray:
    """For each directed edge (a, b), the index of (b, a), or -1."""
    key = edges[:, 0].astype(np.int64) * n_vertices + edges[:, 1]
    twin_key = edges[:, 1].astype(np.int64) * n_vertices + edges[:, 0]
    order = np.argsort(key)
    pos = np.searchsorted(key[order], twin_key)
    pos = np.clip(pos, 0, len(key) - 1)
    found = key[order][pos] == twin_key
    return np.where(found, order[pos], -1)


def boundary_loops(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """Closed loops of boundary edges, each as vertex indices in the faces' winding order."""
    edges, _ = _directed_edges(np.asarray(mesh.faces))
    boundary = edges[_twins(edges, len(mesh.vertices)) < 0]
    nxt: dict[int, list[int]] = {}
    for a, b in boundary:
        nxt.setdefault(int(a), []).append(int(b))
    loops = []
    while nxt:
        start = next(iter(nxt))
        loop = [start]
        v = start
        while True:
            outs = nxt.get(v)
            if not outs:
                break
            w = outs.pop()
            if not outs:
                del nxt[v]
            if w == start:
                break
            loop.append(w)
            v = w
        if len(loop) >= 3:
            loops.append(np.asarray(loop))
    return loops


def fill_holes(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Close every boundary loop by a fan of triangles around the loop's centroid (a new vertex),
    wound like the surrounding faces."""
    vertices = [np.asarray(mesh.vertices, dtype=np.float64)]
    faces = [np.asarray(mesh.faces)]
    n = len(vertices[0])
    for loop in boundary_loops(mesh):
        centre = vertices[0][loop].mean(axis=0)
        vertices.append(centre[None])
        a, b = loop, np.roll(loop, -1)
        faces.append(np.c_[b, a, np.full(len(loop), n)])  # boundary edge a->b is walked b->a here
        n += 1
    return trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)


def decimate(mesh: trimesh.Trimesh, keep: float | None = None, *,
             faces: int | None = None, keep_closed: bool = True) -> trimesh.Trimesh:
    """Quadric edge-collapse decimation to ``keep`` of the faces (or to ``faces`` faces).

    With ``keep_closed``, a closed input that the decimation leaves open or non-manifold (a few
    pinched edges, typically where a fan of :func:`fill_holes` or a thin wall collapsed) is first
    repaired (:func:`repair_closed`); if that fails it is decimated again to 1.5 times as many
    faces, until the result is closed (or nothing is removed).
    """
    import fast_simplification

    target = faces if faces is not None else int(round(keep * len(mesh.faces)))
    target = max(4, min(int(target), len(mesh.faces)))
    closed = keep_closed and mesh.is_watertight
    while target < len(mesh.faces):
        v, f = fast_simplification.simplify(np.asarray(mesh.vertices, np.float64),
                                            np.asarray(mesh.faces, np.int64), target_count=target)
        out = trimesh.Trimesh(v, f, process=False)
        out.remove_unreferenced_vertices()
        if not closed or out.is_watertight:
            return out
        out = repair_closed(out)
        if out.is_watertight:
            return out
        target = int(1.5 * target) + 1
    return mesh


def repair_closed(mesh: trimesh.Trimesh, passes: int = 3) -> trimesh.Trimesh:
    """Remove duplicated faces and every face on an edge shared by more than two faces, keep the
    largest piece and close the holes this leaves; repeated up to ``passes`` times while the mesh
    is not closed. Returns the last attempt (check ``is_watertight``)."""
    for _ in range(passes):
        if mesh.is_watertight:
            break
        faces = np.asarray(mesh.faces)
        key = np.sort(faces, axis=1)
        _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        keep = count[inverse.ravel()] == 1
        edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        _, e_inv, e_count = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
        keep &= ~(e_count[e_inv.ravel()] > 2).reshape(-1, 3).any(axis=1)
        mesh = trimesh.Trimesh(mesh.vertices, faces[keep], process=False)
        mesh.remove_unreferenced_vertices()
        mesh = fill_holes(largest_component(mesh))
    return mesh


def sqrt3_subdivide(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """One step of √3 subdivision (Kobbelt 2000): three times the faces (see the module docstring)."""
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces)
    nv, nf = len(V), len(F)
    edges, face_of = _directed_edges(F)
    twin = _twins(edges, nv)

    # Relax old vertices toward their neighbours' mean (boundary vertices stay).
    undirected = np.unique(np.sort(edges, axis=1), axis=0)
    degree = np.bincount(undirected.ravel(), minlength=nv).astype(np.float64)
    total = np.zeros_like(V)
    np.add.at(total, undirected[:, 0], V[undirected[:, 1]])
    np.add.at(total, undirected[:, 1], V[undirected[:, 0]])
    on_boundary = np.zeros(nv, dtype=bool)
    on_boundary[edges[twin < 0].ravel()] = True
    n = np.maximum(degree, 1)
    alpha = (4 - 2 * np.cos(2 * np.pi / n)) / 9
    relaxed = (1 - alpha[:, None]) * V + alpha[:, None] * total / n[:, None]
    relaxed[on_boundary | (degree == 0)] = V[on_boundary | (degree == 0)]

    centroids = V[F].mean(axis=1)
    m = nv + face_of  # index of the centroid of each directed edge's face
    interior = twin >= 0
    first = interior & (edges[:, 0] < edges[:, 1])  # one of each twin pair
    a, b = edges[first, 0], edges[first, 1]
    mf, mg = m[first], m[twin[first]]
    new = [np.c_[a, mg, mf], np.c_[mg, b, mf]]
    border = ~interior
    new.append(np.c_[edges[border, 0], edges[border, 1], m[border]])
    return trimesh.Trimesh(np.concatenate([relaxed, centroids]), np.concatenate(new), process=False)


def subdivide_decimate(mesh: trimesh.Trimesh, rounds: int = 4, keep: float = 1 / 3) -> trimesh.Trimesh:
    """``rounds`` times: one √3 subdivision (3x faces) then decimation to ``keep`` of the faces."""
    for _ in range(rounds):
        mesh = decimate(sqrt3_subdivide(mesh), keep)
    return mesh
