"""Uniformly spaced surface points: the thesis's per-triangle subdivision, with lookup from a hit.

The thesis stores measurements on points spread evenly over each triangle by a quaternary
subdivision tree of depth ``min(log2(a / b), d_max)`` (``a`` the triangle's size, ``b`` the wanted
spacing): every level splits a triangle into four by its edge midpoints. Every leaf of a tree of
uniform depth ``d`` is one cell of the ``2^d x 2^d`` barycentric grid of the triangle (``4^d``
cells, "lower" and "upper" half-squares), so the leaf that holds a hit follows from its
barycentric coordinates in constant time, without walking the tree. Each cell's point is its
centroid; large triangles get deep trees and small ones shallow, so the spacing is near ``b``
everywhere (within the factor 2 that a power-of-two depth allows, and only coarser on triangles
capped at ``d_max``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SurfacePoints", "subdivision_depths", "build_surface_points"]


def subdivision_depths(vertices: np.ndarray, faces: np.ndarray, spacing_m: float,
                       max_depth: int = 6) -> np.ndarray:
    """Depth per triangle, ``clip(ceil(log2(a / b)), 0, d_max)`` with ``a`` the longest edge.

    Parameters
    ----------
    vertices, faces : np.ndarray
        The mesh, (V, 3) metres and (F, 3) indices.
    spacing_m : float
        Wanted spacing ``b`` between points, metres.
    max_depth : int
        ``d_max``: caps the points per triangle at ``4**d_max``.
    """
    if not spacing_m > 0:
        raise ValueError(f"spacing_m must be > 0, got {spacing_m}")
    tri = vertices[faces]
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    with np.errstate(divide="ignore"):
        depth = np.ceil(np.log2(np.maximum(edges, 1e-30) / spacing_m))
    return np.clip(depth, 0, max_depth).astype(np.int64)


@dataclass(frozen=True)
class SurfacePoints:
    """Points on a mesh, one per leaf of each triangle's subdivision.

    Attributes
    ----------
    depth : np.ndarray
        (F,) subdivision depth per triangle.
    offset : np.ndarray
        (F,) index of each triangle's first cell in the dense cell table.
    cell_to_point : np.ndarray
        Dense table over ``2 * 4**depth`` cells per triangle (``(i, j, upper)``, the out-of-triangle
        ones included): point index, or -1 where the cell lies outside the triangle.
    triangle : np.ndarray
        (P,) triangle of each point.
    barycentric : np.ndarray
        (P, 2) barycentrics ``(b1, b2)`` of each point.
    position : np.ndarray
        (P, 3) positions, metres (object frame).
    normal : np.ndarray
        (P, 3) unit shading normals.
    """

    depth: np.ndarray
    offset: np.ndarray
    cell_to_point: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    position: np.ndarray
    normal: np.ndarray

    def __len__(self) -> int:
        return len(self.triangle)

    def lookup(self, triangle: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
        """Point index (N,) of hits given by triangle (N,) and barycentrics (N, 2)."""
        n = (1 << self.depth[triangle]).astype(np.float64)
        x = barycentric[:, 0] * n
        y = barycentric[:, 1] * n
        i = np.clip(np.floor(x), 0, n - 1)
        j = np.clip(np.floor(y), 0, n - 1)
        upper = ((x - i) + (y - j) >= 1.0) & (i + j <= n - 2)
        # A hit on the far edge (i + j = n - 1, upper) belongs to the lower cell beside it.
        fix = (i + j > n - 1)
        i = np.where(fix, n - 1 - j, i)
        cell = (i * n + j) * 2 + upper
        return self.cell_to_point[self.offset[triangle] + cell.astype(np.int64)]


def build_surface_points(vertices: np.ndarray, faces: np.ndarray, spacing_m: float,
                         max_depth: int = 6, vertex_normals: np.ndarray | None = None) -> SurfacePoints:
    """Subdivide every triangle (:func:`subdivision_depths`) and place a point in each leaf.

    Parameters
    ----------
    vertices, faces : np.ndarray
        The mesh, (V, 3) metres and (F, 3) indices.
    spacing_m : float
        Wanted spacing between points, metres.
    max_depth : int
        Deepest subdivision.
    vertex_normals : np.ndarray, optional
        (V, 3) for smooth normals at the points; face normals when omitted.
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    depth = subdivision_depths(vertices, faces, spacing_m, max_depth)
    cells = 2 * (1 << depth) ** 2
    offset = np.concatenate([[0], np.cumsum(cells)[:-1]]).astype(np.int64)
    cell_to_point = np.full(int(cells.sum()), -1, dtype=np.int64)
    tris, barys, cell_ids = [], [], []
    # One grid per distinct depth, shared by every triangle of that depth.
    for d in np.unique(depth):
        n = 1 << int(d)
        ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        ii, jj = ii.ravel(), jj.ravel()
        lower = ii + jj <= n - 1
        upper = ii + jj <= n - 2
        grid_i = np.concatenate([ii[lower], ii[upper]])
        grid_j = np.concatenate([jj[lower], jj[upper]])
        grid_u = np.concatenate([np.zeros(lower.sum(), np.int64), np.ones(upper.sum(), np.int64)])
        third = np.where(grid_u == 1, 2.0 / 3.0, 1.0 / 3.0)
        grid_b = np.stack([(grid_i + third) / n, (grid_j + third) / n], axis=1)
        grid_cell = (grid_i * n + grid_j) * 2 + grid_u
        sel = np.nonzero(depth == d)[0]
        tris.append(np.repeat(sel, len(grid_cell)))
        barys.append(np.tile(grid_b, (len(sel), 1)))
        cell_ids.append((offset[sel][:, None] + grid_cell[None, :]).ravel())
    triangle = np.concatenate(tris)
    barycentric = np.concatenate(barys)
    cell_id = np.concatenate(cell_ids)
    cell_to_point[cell_id] = np.arange(len(cell_id))
    f = faces[triangle]
    b1, b2 = barycentric[:, :1], barycentric[:, 1:]
    w = (1.0 - b1 - b2, b1, b2)
    position = sum(w[k] * vertices[f[:, k]] for k in range(3))
    if vertex_normals is None:
        e = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
        normal = e[triangle]
    else:
        normal = sum(w[k] * np.asarray(vertex_normals, np.float64)[f[:, k]] for k in range(3))
    normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    return SurfacePoints(depth, offset, cell_to_point, triangle, barycentric, position, normal)
