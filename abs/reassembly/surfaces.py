"""Thresholds and iso-surfaces of a CT volume (marching cubes from scikit-image).

The markers are the densest material; the glass threshold only removes air and noise.
:func:`auto_thresholds` picks both from the histogram: the air and glass levels are the two
histogram peaks either side of Otsu's threshold, the marker level the median of the volume's
densest voxels (a fixed count, so that it does not depend on the share of the volume the
markers fill); the glass threshold lies half-way from air to glass, the marker threshold half-way from
glass to the marker level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from abs.errors import InputError
from abs.reassembly.volume import Volume

__all__ = ["Thresholds", "auto_thresholds", "iso_surface"]


@dataclass(frozen=True)
class Thresholds:
    """Grey-value thresholds and the levels they came from.

    Attributes
    ----------
    glass, marker : float
        Iso-levels of the glass and marker surfaces.
    air_level, glass_level, marker_level : float
        The grey values of air, glass and markers the thresholds were placed between
        (``nan`` where a threshold was given rather than found).
    """

    glass: float
    marker: float
    air_level: float = float("nan")
    glass_level: float = float("nan")
    marker_level: float = float("nan")


def _peak(values: np.ndarray, bins: int = 256) -> float:
    hist, edges = np.histogram(values, bins=bins)
    i = int(np.argmax(hist))
    return float(0.5 * (edges[i] + edges[i + 1]))


def auto_thresholds(volume: Volume, *, marker_voxels: int = 50,
                    min_marker_contrast: float = 1.5, sample: int = 2_000_000,
                    seed: int = 0) -> Thresholds:
    """Glass and marker thresholds from the volume's histogram.

    Parameters
    ----------
    volume : Volume
        The scan.
    marker_voxels : int
        The marker level is the median of this many densest voxels (all inside markers when the
        markers hold a few voxels each).
    min_marker_contrast : float
        The marker level must lie at least this many times as far above air as glass does;
        otherwise the volume has no marker material.
    sample : int
        At most this many voxels (drawn at random) make the histogram.

    Raises
    ------
    InputError
        A volume without two materials, or without markers denser than the glass.
    """
    from skimage.filters import threshold_otsu

    flat = np.asarray(volume.data).reshape(-1)
    if flat.size > sample:
        flat = flat[np.random.default_rng(seed).integers(0, flat.size, sample)]
    flat = flat.astype(np.float64)
    if np.ptp(flat) == 0:
        raise InputError(volume.source, "", "the volume is constant: no object in it")
    t = threshold_otsu(flat)
    air = _peak(flat[flat <= t])
    glass = _peak(flat[flat > t])
    every = np.asarray(volume.data).reshape(-1)
    n_top = min(marker_voxels, every.size)
    top = float(np.median(np.partition(every, every.size - n_top)[-n_top:]))
    if not (glass > air) or top - air < min_marker_contrast * (glass - air):
        raise InputError(volume.source, "", (
            f"no markers found: the densest voxels (median of the {n_top} densest: {top:.0f}) "
            f"are not {min_marker_contrast:g}x as far above air ({air:.0f}) as the glass "
            f"({glass:.0f}); give --marker-threshold if the markers are there"))
    return Thresholds(glass=air + 0.5 * (glass - air), marker=glass + 0.5 * (top - glass),
                      air_level=air, glass_level=glass, marker_level=top)


def iso_surface(volume: Volume, level: float, *, mask: np.ndarray | None = None) -> trimesh.Trimesh:
    """The iso-surface at ``level`` as a mesh in the volume frame (mm, outward normals).

    The volume is padded by one voxel below ``level`` so that the surface is closed where the
    object touches the volume's border. ``mask`` (bool, volume shape) limits the surface to
    voxels where it is true (others are treated as below ``level``).

    Raises
    ------
    InputError
        No voxel above ``level``.
    """
    from skimage.measure import marching_cubes

    data = np.asarray(volume.data, dtype=np.float32)
    if mask is not None:
        data = np.where(mask, data, np.float32(min(level - 1, float(data.min()))))
    if not np.any(data > level):
        raise InputError(volume.source, "", f"no voxel above the threshold {level:g}")
    low = np.float32(min(level - 1, float(data.min())))
    padded = np.pad(data, 1, constant_values=low)
    verts, faces, _, _ = marching_cubes(padded, level=level, spacing=volume.spacing_zyx,
                                        allow_degenerate=False)
    verts = verts - np.asarray(volume.spacing_zyx)  # undo the padding
    verts = verts[:, ::-1]  # (z, y, x) -> (x, y, z); with skimage's winding the normals point out
    mesh = trimesh.Trimesh(verts, faces, process=False)
    mesh.merge_vertices()
    return mesh
