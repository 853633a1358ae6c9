"""Micropolygon labelling: one material label per face of a scanned background mesh, from label
images of calibrated photographs (docs/reassembly.md).

1. The mesh is subdivided (midpoint, 1 -> 4 faces, only the faces still too large) until every
   face a camera sees is smaller than a pixel's footprint there: its longest edge at most
   ``depth / f`` (metres per pixel at the face's depth, the finest of the cameras that see it).
   Then a face's vertices fall within about one pixel of each other in every photograph.
2. Each vertex is projected into every photograph and takes the label of the pixel it lands on
   (``0``, unknown, outside the image or on an unknown pixel). A face takes the label most of its
   projected vertices landed on, over all photographs; ties go to the lower label.
3. Faces with no known vote (unseen, or seen only on watershed lines and masked pixels) take the
   label of the nearest labelled face (face centroids, Euclidean: on a background mesh the
   nearest face in space is a neighbour on the surface).

Cameras are OpenCV pinholes (docs/conventions.md: ``x_cam = R X + t``, pixel ``(0, 0)`` the
centre of the top-left pixel), metres. Occlusion is not tested: whatever stands between a
camera and the mesh votes its own label onto the faces behind it, so mask such objects out of
the photographs (the capture format's ``mask``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from abs.camera.pinhole import project
from abs.errors import InputError

__all__ = ["LabelCamera", "LabelResult", "pixel_footprint", "subdivide_to_footprint", "label_mesh"]


@dataclass(frozen=True)
class LabelCamera:
    """A calibrated label image.

    Attributes
    ----------
    name : str
        The view's name (in errors and reports).
    K, R, t : arrays
        OpenCV intrinsics (pixels), world-to-camera rotation and translation (metres).
    labels : (H, W) int array
        ``0`` unknown, ``1..n`` labels.
    source : str, optional
        Where the camera came from (``cameras.json``), named in errors.
    field : str, optional
        Its field there (``views[2]``), named in errors; default ``views[<name>]``.
    """

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    labels: np.ndarray
    source: str | None = None
    field: str | None = None

    @property
    def where(self) -> str:
        """The field named in errors."""
        return self.field or f"views[{self.name}]"


@dataclass(frozen=True)
class LabelResult:
    """A labelled mesh.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        The subdivided mesh (metres, the input's frame).
    face_labels : (F,) int32
        Label per face, ``1..n``.
    voted : (F,) bool
        Faces labelled by their own votes (the others by their nearest labelled face).
    votes_per_view : dict
        View name -> vertices that landed on a known label.
    worst_edge_px : float
        Largest ratio of a seen face's longest edge to its pixel footprint (<= 1 when the
        subdivision finished).
    rounds : int
        Subdivision rounds run.
    """

    mesh: trimesh.Trimesh
    face_labels: np.ndarray
    voted: np.ndarray
    votes_per_view: dict
    worst_edge_px: float
    rounds: int


def _seen(cam: LabelCamera, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which faces (corners ``tri``, (F, 3, 3) metres) can fall in the image, and their depth.

    A face counts when its centroid is in front of the camera and the box around its projected
    corners overlaps the image (a large face may cover the image with all corners outside it);
    a face with a corner behind the camera has no such box and counts when its centroid does.
    """
    h, w = cam.labels.shape
    centroid = tri.mean(axis=1)
    depth = centroid @ cam.R[2] + cam.t[2]
    uv = project(cam.K, cam.R, cam.t, tri.reshape(-1, 3)).reshape(-1, 3, 2)
    behind = np.isnan(uv).any(axis=(1, 2))
    lo = np.where(np.isnan(uv), np.inf, uv).min(axis=1)
    hi = np.where(np.isnan(uv), -np.inf, uv).max(axis=1)
    overlap = (hi[:, 0] >= -0.5) & (lo[:, 0] <= w - 0.5) & (hi[:, 1] >= -0.5) & (lo[:, 1] <= h - 0.5)
    return (depth > 0) & (overlap | behind), depth


def pixel_footprint(tri: np.ndarray, cameras: Sequence[LabelCamera]) -> np.ndarray:
    """Metres per pixel at each face, the finest over the cameras that see it.

    ``depth / sqrt(fx fy)``: the side of a pixel's footprint on a plane facing the camera at the
    face centroid's depth (an oblique face's footprint is longer, so this is the stricter one).

    Parameters
    ----------
    tri : (F, 3, 3) array
        Face corners, metres.
    cameras : sequence of LabelCamera

    Returns
    -------
    (F,) float64
        Metres; ``inf`` for faces no camera sees.
    """
    out = np.full(len(tri), np.inf)
    for cam in cameras:
        seen, depth = _seen(cam, tri)
        f = np.sqrt(cam.K[0, 0] * cam.K[1, 1])
        out = np.where(seen, np.minimum(out, depth / f), out)
    return out


def _longest_edge(tri: np.ndarray) -> np.ndarray:
    return np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)


def subdivide_to_footprint(mesh: trimesh.Trimesh, cameras: Sequence[LabelCamera],
                           max_faces: int = 2_000_000, max_rounds: int = 20
                           ) -> tuple[trimesh.Trimesh, float, int]:
    """Split the faces larger than a pixel's footprint until none is.

    Only the faces still too large are split (1 -> 4 at the edge midpoints, trimesh), so a
    face's neighbours may keep a vertex in the middle of a shared edge (a T-junction: no gap,
    the new vertex lies on the old edge).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Metres.
    cameras : sequence of LabelCamera
    max_faces : int
        Refuse to grow beyond this many faces.
    max_rounds : int
        Refuse to run more subdivision rounds than this.

    Returns
    -------
    mesh : trimesh.Trimesh
    worst : float
        Largest longest-edge / footprint ratio left (<= 1).
    rounds : int

    Raises
    ------
    InputError
        The mesh would need more than ``max_faces`` faces (a camera very close to it, or a
        mesh in the wrong unit: it must be in metres).
    """
    vertices, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    for rounds in range(max_rounds + 1):
        tri = vertices[faces]
        ratio = _longest_edge(tri) / pixel_footprint(tri, cameras)
        big = np.flatnonzero(ratio > 1)
        worst = float(ratio.max()) if len(ratio) else 0.0
        if len(big) == 0:
            return trimesh.Trimesh(vertices, faces, process=False), worst, rounds
        if rounds == max_rounds or len(faces) + 3 * len(big) > max_faces:
            break
        vertices, faces = trimesh.remesh.subdivide(vertices, faces, face_index=big)
    raise InputError(None, "mesh", f"a pixel's footprint needs more than {max_faces} faces "
                                   f"({len(faces)} after {rounds} rounds, longest edge still "
                                   f"{worst:.1f} footprints): is the mesh in metres?")


def _vertex_votes(vertices: np.ndarray, cam: LabelCamera) -> np.ndarray:
    """The label each vertex lands on in ``cam`` (0 outside the image or behind the camera)."""
    h, w = cam.labels.shape
    uv = project(cam.K, cam.R, cam.t, vertices)
    with np.errstate(invalid="ignore"):
        col, row = np.rint(uv[:, 0]), np.rint(uv[:, 1])
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    out = np.zeros(len(vertices), dtype=np.int64)
    out[inside] = cam.labels[row[inside].astype(int), col[inside].astype(int)]
    return out


def label_mesh(mesh: trimesh.Trimesh, cameras: Sequence[LabelCamera], n_labels: int,
               max_faces: int = 2_000_000) -> LabelResult:
    """Subdivide ``mesh`` to the pixel footprint and give each face a label.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The scanned background, metres, world frame (the cameras' frame).
    cameras : sequence of LabelCamera
        Label images (``0`` unknown, ``1..n_labels``) with their cameras.
    n_labels : int
        Largest label.
    max_faces : int
        See :func:`subdivide_to_footprint`.

    Returns
    -------
    LabelResult

    Raises
    ------
    InputError
        A camera that sees none of the mesh (naming the view and its ``cameras.json``), label
        images with no known label anywhere on the mesh, an empty mesh.
    """
    if len(mesh.faces) == 0:
        raise InputError(None, "mesh", "has no faces")
    tri = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)]
    for cam in cameras:
        if not _seen(cam, tri)[0].any():
            raise InputError(cam.source, cam.where, f"camera {cam.name!r} sees none of the mesh (wrong "
                                                    "camera, or a mesh not in the world frame in metres?)")
    mesh, worst, rounds = subdivide_to_footprint(mesh, cameras, max_faces)
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    counts = np.zeros((len(faces), n_labels + 1), dtype=np.int64)
    per_view = {}
    for cam in cameras:
        votes = _vertex_votes(vertices, cam)
        per_view[cam.name] = int(np.count_nonzero(votes))
        if votes.max(initial=0) > n_labels:
            raise InputError(cam.source, cam.where, f"label image holds label "
                                                    f"{int(votes.max())}, more than {n_labels}")
        for corner in range(3):
            np.add.at(counts, (np.arange(len(faces)), votes[faces[:, corner]]), 1)
    counts[:, 0] = 0  # unknown does not vote
    voted = counts.max(axis=1) > 0
    if not voted.any():
        raise InputError(None, "labels", "no face of the mesh landed on a known label in any "
                                         "photograph (empty segmentation where the mesh is seen)")
    labels = np.argmax(counts, axis=1).astype(np.int32)
    centroids = vertices[faces].mean(axis=1)
    if not voted.all():
        _, nearest = cKDTree(centroids[voted]).query(centroids[~voted])
        labels[~voted] = labels[voted][nearest]
    return LabelResult(mesh, labels, voted, per_view, worst, rounds)
