"""Markers in calibrated photographs: detections of every camera pair matched, triangulated and
reduced to one world point per marker (docs/reassembly.md, "Markers in stereo photographs").

Per pair of images: the detections (:mod:`.circles`) are matched by Sampson distance under the
calibration's fundamental matrix (:mod:`.epipolar`; ambiguous detections reported and left out),
triangulated (:mod:`.triangulation`); points behind a camera are dropped, and so, when a glass
mesh is given, are points that one of the pair's cameras sees through the glass
(:mod:`.through_glass`). The points of all pairs are then clustered, one point per marker.

Units: metres (world frame of docs/conventions.md), pixels.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from abs.errors import InputError
from abs.reassembly.circles import Circles
from abs.reassembly.epipolar import fundamental_matrix, match_epipolar
from abs.reassembly.through_glass import seen_through_glass
from abs.reassembly.triangulation import cluster_points, triangulate

__all__ = ["MarkerImage", "StereoMarkers", "locate_markers"]


@dataclass(frozen=True)
class MarkerImage:
    """The detections of one calibrated photograph.

    Attributes
    ----------
    name : str
        The camera (view) name, for reports.
    image : str
        The photograph's path, for messages.
    K, R, t : np.ndarray
        Camera of ``cameras.json``: intrinsics (pixels), world-to-camera rotation and
        translation (metres).
    circles : Circles
        Its detections.
    """

    name: str
    image: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    circles: Circles

    @property
    def camera(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.K, self.R, self.t

    @property
    def centre(self) -> np.ndarray:
        """Camera centre, world frame, metres."""
        return -np.asarray(self.R).T @ np.asarray(self.t).reshape(3)


@dataclass(frozen=True)
class StereoMarkers:
    """Result of :func:`locate_markers`.

    Attributes
    ----------
    points_m : np.ndarray
        ``(n, 3)`` one point per marker, world frame, metres.
    error_px : np.ndarray
        ``(n,)`` reprojection error of each point (the larger of its two views'), pixels.
    sources : list of dict
        Per marker: the camera pair and the detections its point was triangulated from, and how
        many points its cluster held (``{"cameras": [a, b], "pixels": [[u, v], [u, v]],
        "detections": [i, j], "points": k}``).
    ambiguous : list of dict
        Detections left out because several detections of the other image lie on their epipolar
        line: ``{"cameras": [a, b], "left": i, "right": [j, ...]}`` (or the mirror).
    through_glass : list of dict
        Triangulated points dropped because a camera sees them through the glass:
        ``{"cameras": [a, b], "point_m": [x, y, z], "seen_through_glass_by": [name, ...]}``.
    dropped : list of dict
        Other points dropped: behind a camera, or outliers of their cluster.
    """

    points_m: np.ndarray
    error_px: np.ndarray
    sources: list[dict] = field(default_factory=list)
    ambiguous: list[dict] = field(default_factory=list)
    through_glass: list[dict] = field(default_factory=list)
    dropped: list[dict] = field(default_factory=list)


def _pair_points(a: MarkerImage, b: MarkerImage, tol_px: float, glass, glass_margin_m: float,
                 report: dict) -> list[tuple]:
    """``(point, error, source)`` for each sure match of images ``a`` and ``b``."""
    F = fundamental_matrix(a.K, a.R, a.t, b.K, b.R, b.t)
    matches = match_epipolar(a.circles.centres_px, b.circles.centres_px, F, tol_px)
    names = [a.name, b.name]
    report["ambiguous"] += [{"cameras": names, **amb} for amb in matches.ambiguous]
    if len(matches.pairs) == 0:
        return []
    x1 = a.circles.centres_px[matches.pairs[:, 0]]
    x2 = b.circles.centres_px[matches.pairs[:, 1]]
    points, error, in_front = triangulate(a.camera, b.camera, x1, x2)
    behind_glass = np.zeros((len(points), 2), bool)
    if glass is not None:
        behind_glass[in_front] = seen_through_glass(points[in_front], np.stack([a.centre, b.centre]),
                                                    glass, glass_margin_m)
    out = []
    for k, (i, j) in enumerate(matches.pairs):
        source = {"cameras": names, "pixels": [x1[k].tolist(), x2[k].tolist()],
                  "detections": [int(i), int(j)]}
        if not in_front[k]:
            report["dropped"].append({**source, "why": "behind a camera"})
        elif behind_glass[k].any():
            seen_by = [n for n, f in zip(names, behind_glass[k]) if f]
            report["through_glass"].append({**source, "point_m": points[k].tolist(),
                                            "seen_through_glass_by": seen_by})
        else:
            out.append((points[k], float(error[k]), source))
    return out


def locate_markers(images: Sequence[MarkerImage], *, tol_px: float = 1.5, merge_m: float = 1e-3,
                   outlier_m: float = 0.5e-3, glass=None, glass_margin_m: float = 2e-3,
                   min_markers: int = 3) -> StereoMarkers:
    """World points of the markers detected in two or more calibrated images.

    Parameters
    ----------
    images : sequence of MarkerImage
        At least two; every pair is matched.
    tol_px : float
        Largest Sampson distance of a match, pixels.
    merge_m, outlier_m : float
        Clustering distances, metres (see :func:`.triangulation.cluster_points`).
    glass : trimesh.Trimesh, optional
        The glass object in the world frame (its mesh placed by a first guess). Points a camera
        sees through it are dropped and reported in ``through_glass``.
    glass_margin_m : float
        See :func:`.through_glass.seen_through_glass`.
    min_markers : int
        Fewer markers than this is an error (placement needs 3).

    Raises
    ------
    InputError
        Fewer than two images, or fewer than ``min_markers`` markers left, naming the images
        and what was found, ambiguous and dropped.
    """
    if len(images) < 2:
        raise InputError(None, "images", f"stereo needs at least 2 images, got {len(images)}")
    report: dict[str, list] = {"ambiguous": [], "through_glass": [], "dropped": []}
    found = []
    for a, b in itertools.combinations(images, 2):
        found += _pair_points(a, b, tol_px, glass, glass_margin_m, report)
    clusters = cluster_points(np.array([f[0] for f in found]).reshape(-1, 3),
                              np.array([f[1] for f in found]), merge_m=merge_m, outlier_m=outlier_m)
    points, errors, sources = [], [], []
    for c in clusters:
        points.append(c.point)
        errors.append(c.error_px)
        sources.append({**found[c.index][2], "points": int(len(c.members))})
        report["dropped"] += [{**found[k][2], "why": "outlier of its cluster"} for k in c.outliers]
    if len(points) < min_markers:
        detected = ", ".join(f"{m.image} ({m.name}): {len(m.circles)}" for m in images)
        why = []
        if report["ambiguous"]:
            why.append(f"{len(report['ambiguous'])} ambiguous on an epipolar line")
        if report["through_glass"]:
            why.append(f"{len(report['through_glass'])} seen through glass")
        if report["dropped"]:
            why.append(f"{len(report['dropped'])} behind a camera or outliers")
        raise InputError(None, "markers", (
            f"fewer than {min_markers} matched markers: {len(points)} found in "
            f"{' and '.join(m.image for m in images)} (detections: {detected}"
            f"{'; left out: ' + ', '.join(why) if why else ''}); check the cameras, the radius "
            "range or the Sampson tolerance"))
    return StereoMarkers(np.array(points).reshape(-1, 3), np.array(errors), sources,
                         report["ambiguous"], report["through_glass"], report["dropped"])
