"""Glass surfaces that coincide with another surface: where rounding decides what a ray meets.

A glass bowl modelled "resting on the cloth" with its flat base in the cloth's plane has two
surfaces in one place. A ray leaving the glass through that base meets the cloth at distance zero,
or skips it, depending on the ray tracer's rounding and self-intersection offsets: Embree (the CPU
variant) and OptiX (the GPU variant) decide differently. Measured on the glass suite's framed bowl
(``benchmarks/glass_fit.py``, 60x50, 4 x 16384 spp per backend): the GPU's renders of the same
scene were 0.54 % darker than the CPU's over the pixels seen through the bowl (+- 0.06 %), all of
it in the band seen through the base, and a fit's absorption moves by 1 /m per 0.55 % there, so
the same photographs gave absorptions about 1 /m lower on the GPU. With the bowl lifted 0.1 mm the
backends agree there (+0.08 +- 0.09 %). Real glass on a cloth touches it at the fibres; a gap of a
tenth of a millimetre renders the same and is well defined.

:func:`coincident_area` measures such contact on two triangle meshes (numpy arrays);
:func:`coincident_surfaces` finds it between a compiled scene's glass objects and every other
shape, as the renderer holds them (world space, after ``to_world``). Fits report it among their
checks (:mod:`abs.fitting.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["CoincidentSurface", "coincident_area", "coincident_surfaces", "TOLERANCE_M",
           "MIN_AREA_M2"]

#: Surfaces closer than this (m) count as one: about 20 times the offset (relative to the scene's
#: extent, float32) by which Mitsuba lifts a ray off the surface it leaves, for scenes a metre
#: across; a gap of 0.1 mm is 10 times clear of it.
TOLERANCE_M = 1e-5

#: Coincident glass area (m²) below which nothing is reported: a sphere resting on a plane
#: touches it at one vertex, whose neighbouring faces rise off it.
MIN_AREA_M2 = 1e-6

# Point-triangle pairs evaluated per batch (memory: about 40 floats each).
_BATCH = 1 << 20


def _closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest points on triangles ``(a, b, c)`` to points ``p`` (each shape (n, 3), paired row
    by row): the Voronoi-region walk of Ericson, *Real-Time Collision Detection* 5.1.5."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        out = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        t_ab, t_ac = d1 / (d1 - d3), d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    edge_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    out[edge_bc] = (b + (c - b) * t_bc[:, None])[edge_bc]
    edge_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    out[edge_ac] = (a + ac * t_ac[:, None])[edge_ac]
    edge_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    out[edge_ab] = (a + ab * t_ab[:, None])[edge_ab]
    corner_c = (d6 >= 0) & (d5 <= d6)
    out[corner_c] = c[corner_c]
    corner_b = (d3 >= 0) & (d4 <= d3)
    out[corner_b] = b[corner_b]
    corner_a = (d1 <= 0) & (d2 <= 0)
    out[corner_a] = a[corner_a]
    # Degenerate (zero-area) triangles: their nearest corner.
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any():
        corners = np.stack([a[bad], b[bad], c[bad]], 1)
        nearest = np.argmin(np.linalg.norm(corners - p[bad, None], axis=2), axis=1)
        out[bad] = corners[np.arange(len(nearest)), nearest]
    return out


def _near_surface(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                  tolerance: float) -> np.ndarray:
    """Whether each point lies within ``tolerance`` of the triangle mesh ``(vertices, faces)``."""
    near = np.zeros(len(points), bool)
    if not len(points) or not len(faces):
        return near
    tri = vertices[faces]  # (m, 3, 3)
    lower, upper = tri.min(axis=(0, 1)) - tolerance, tri.max(axis=(0, 1)) + tolerance
    inside = np.all((points >= lower) & (points <= upper), axis=1)
    if not inside.any():
        return near
    centroids = tri.mean(axis=1)
    radius = np.linalg.norm(tri - centroids[:, None], axis=2).max(axis=1)
    index = np.flatnonzero(inside)
    # Triangles grouped by size (powers of two), each group searched within its own largest
    # radius: one floor-sized triangle must not make every point a candidate of every small one.
    size_class = np.floor(np.log2(np.maximum(radius, 1e-12))).astype(int)
    for cls in np.unique(size_class):
        members = np.flatnonzero(size_class == cls)
        reach = float(radius[members].max()) + tolerance
        candidates = cKDTree(centroids[members]).query_ball_point(points[index], reach)
        pairs_p = np.repeat(index, [len(c) for c in candidates])
        pairs_t = members[np.fromiter((t for c in candidates for t in c), np.int64, count=len(pairs_p))]
        for start in range(0, len(pairs_p), _BATCH):
            p, t = pairs_p[start:start + _BATCH], pairs_t[start:start + _BATCH]
            q = _closest_on_triangles(points[p], tri[t, 0], tri[t, 1], tri[t, 2])
            near[p[np.linalg.norm(points[p] - q, axis=1) <= tolerance]] = True
    return near


def coincident_area(vertices: np.ndarray, faces: np.ndarray, other_vertices: np.ndarray,
                    other_faces: np.ndarray, tolerance_m: float = TOLERANCE_M) -> float:
    """Area of one mesh's faces that lie on another mesh's surface.

    Parameters
    ----------
    vertices, faces : ndarray, shapes (n, 3) and (k, 3)
        The first mesh (positions in m, triangle vertex indices).
    other_vertices, other_faces : ndarray
        The second mesh, in the same frame.
    tolerance_m : float
        A face counts when all three of its vertices lie within this distance (m) of the second
        mesh's surface.

    Returns
    -------
    float
        The counted faces' total area, m².
    """
    vertices, faces = np.asarray(vertices, float), np.asarray(faces, np.int64)
    on = _near_surface(vertices, np.asarray(other_vertices, float), np.asarray(other_faces, np.int64),
                       float(tolerance_m))
    lying = on[faces].all(axis=1)
    if not lying.any():
        return 0.0
    tri = vertices[faces[lying]]
    return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


@dataclass(frozen=True)
class CoincidentSurface:
    """A glass object's surface lying on another object's surface.

    Attributes
    ----------
    glass, other : str
        The objects' names in the scene file.
    area_m2 : float
        The glass's surface area lying within :data:`TOLERANCE_M` of the other's.
    """

    glass: str
    other: str
    area_m2: float

    def message(self) -> str:
        """The warning a fit prints and writes into ``fit.json``'s checks."""
        return (f"{self.glass}'s surface lies on {self.other}'s over {self.area_m2 * 1e4:.3g} cm^2 "
                f"(within {TOLERANCE_M * 1e6:.0f} um): where two surfaces coincide, rounding decides "
                f"which one a ray meets, so renders differ between the CPU and the GPU and between "
                f"renderers (measured: 0.5 % where a bowl's base sat on the cloth, 1 /m of fitted "
                f"absorption). Leave a gap: lift {self.glass} by 0.1 mm (its mesh or to_world).")


def coincident_surfaces(compiled, tolerance_m: float = TOLERANCE_M,
                        min_area_m2: float = MIN_AREA_M2) -> list[CoincidentSurface]:
    """Glass objects of a compiled scene whose surface lies on another object's.

    Parameters
    ----------
    compiled : CompiledScene
        Its Mitsuba shapes are read as the renderer holds them (world space).
    tolerance_m : float
        Distance (m) under which surfaces count as one.
    min_area_m2 : float
        Smallest coincident area (m²) reported.

    Returns
    -------
    list of CoincidentSurface
        Empty when every glass surface stands clear of the others.
    """
    import mitsuba as mi

    names = {shape_id: name for name, shape_id in compiled.shape_ids.items()}
    transmissive = {name for name, m in compiled.scene.materials.items() if m.transmissive}
    meshes = []
    for shape in compiled.mitsuba_scene.shapes():
        params = mi.traverse(shape)
        if "vertex_positions" not in params or "faces" not in params:
            continue  # not a triangle mesh (an analytic shape): nothing to compare here
        meshes.append((names.get(shape.id(), shape.id()), shape.bsdf().id() in transmissive,
                       np.asarray(params["vertex_positions"], float).reshape(-1, 3),
                       np.asarray(params["faces"], np.int64).reshape(-1, 3)))
    found = []
    for name, glass, vertices, faces in meshes:
        if not glass:
            continue
        for other, _, other_vertices, other_faces in meshes:
            if other == name:
                continue
            area = coincident_area(vertices, faces, other_vertices, other_faces, tolerance_m)
            if area >= min_area_m2:
                found.append(CoincidentSurface(name, other, area))
    return found
