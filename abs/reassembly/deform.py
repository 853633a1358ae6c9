"""Soft deformation: push a soft mesh (the tablecloth) down where a hard one (the glass) would
poke through it.

1. Contact vertices: the vertices of each mesh within ``fraction`` (the seed: 7 %) of the hard
   object's bounding-box diagonal of the other mesh's vertices.
2. A least-squares plane through the soft contact vertices, its normal oriented so that the
   centre of the hard object's bounding box lies in its upper half-space.
3. Each soft contact vertex moves along the normal, if needed, to ``margin`` below the lowest of
   its ``k`` nearest hard contact vertices (nearest within the plane).

Vertices that are not contact vertices never move. The soft mesh must be fine enough for the
contact (``subdivide_to_size`` in :func:`refine`): a tablecloth of two triangles cannot bend.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from abs.errors import InputError

__all__ = ["Deformation", "deform_soft", "refine"]


@dataclass(frozen=True)
class Deformation:
    """The result of :func:`deform_soft`.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        The deformed soft mesh (same vertices and faces, some moved).
    moved : np.ndarray
        Indices of the soft vertices that moved.
    soft_contact, hard_contact : np.ndarray
        Indices of the contact vertices of each mesh.
    normal : np.ndarray
        ``(3,)`` unit normal of the contact plane (pointing toward the hard object).
    max_push : float
        Largest displacement, in the meshes' unit.
    """

    mesh: trimesh.Trimesh
    moved: np.ndarray
    soft_contact: np.ndarray
    hard_contact: np.ndarray
    normal: np.ndarray
    max_push: float


def refine(mesh: trimesh.Trimesh, max_edge: float) -> trimesh.Trimesh:
    """The mesh subdivided until no edge is longer than ``max_edge`` (same surface)."""
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge, max_iter=20)
    return trimesh.Trimesh(v, f, process=True)


def deform_soft(soft: trimesh.Trimesh, hard: trimesh.Trimesh, *, fraction: float = 0.07,
                k: int = 8, margin: float = 0.0) -> Deformation:
    """Push ``soft`` below ``hard`` at their contact (see the module docstring).

    Parameters
    ----------
    soft, hard : trimesh.Trimesh
        The meshes, in one frame and unit (world, metres, in a scene).
    fraction : float
        Contact distance as a fraction of the hard bounding-box diagonal.
    k : int
        Hard contact vertices (nearest within the plane) a soft vertex must lie below.
    margin : float
        Extra clearance below them, in the meshes' unit.

    Raises
    ------
    InputError
        No soft vertex near the hard object (no contact), or fewer than 3 (no plane).
    """
    hard_v = np.asarray(hard.vertices, dtype=np.float64)
    soft_v = np.asarray(soft.vertices, dtype=np.float64)
    lo, hi = hard.bounds
    reach = fraction * float(np.linalg.norm(hi - lo))
    d_soft, _ = cKDTree(hard_v).query(soft_v)
    d_hard, _ = cKDTree(soft_v).query(hard_v)
    soft_contact = np.flatnonzero(d_soft < reach)
    hard_contact = np.flatnonzero(d_hard < reach)
    if len(soft_contact) < 3 or len(hard_contact) == 0:
        raise InputError(None, "contact", (
            f"{len(soft_contact)} soft and {len(hard_contact)} hard vertices lie within "
            f"{reach:g} ({fraction:g} of the hard bounding-box diagonal) of the other mesh; "
            "the meshes do not touch, or the soft mesh is too coarse (refine it)"))
    pts = soft_v[soft_contact]
    origin = pts.mean(axis=0)
    normal = np.linalg.svd(pts - origin, full_matrices=False)[2][-1]
    if (0.5 * (lo + hi) - origin) @ normal < 0:
        normal = -normal
    basis = np.linalg.svd(np.eye(3) - np.outer(normal, normal))[0][:, :2]  # in-plane axes

    hard_h = (hard_v[hard_contact] - origin) @ normal
    tree = cKDTree((hard_v[hard_contact] - origin) @ basis)
    _, nearest = tree.query((pts - origin) @ basis, k=min(k, len(hard_contact)))
    nearest = nearest.reshape(len(pts), -1)
    target = hard_h[nearest].min(axis=1) - margin
    height = (pts - origin) @ normal
    push = np.maximum(height - target, 0.0)
    new_v = soft_v.copy()
    new_v[soft_contact] -= push[:, None] * normal
    out = trimesh.Trimesh(new_v, np.asarray(soft.faces), process=False)
    return Deformation(out, soft_contact[push > 0], soft_contact, hard_contact, normal,
                       float(push.max(initial=0.0)))
