"""A synthetic CT volume whose truth is known: a glass sphere (or a glass mesh, e.g. the bowl of
``scenes/default``) with small spherical markers glued on its surface, density noise and beam-hardening streaks along one axis around the markers.

The streaks make glass next to a marker as dense as a marker, and air next to a marker as dense
as glass, so no single threshold separates glass from markers: the marker threshold picks up
streak tails (which the RANSAC sphere fit must reject) and the glass threshold picks up streaks
in air (which carving and keeping the largest piece remove).

Densities are grey values (``uint16``): air ``air``, glass ``air + glass``, markers
``air + marker``. Partial volume is modelled by a linear ramp of the signed distance over one
voxel; for a mesh the signed distance is exact within 1.5 voxels of its surface (nearest
triangle, the sign from its normal) and the inside elsewhere comes from the connected pieces of
the rest of the grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage
from scipy.spatial import cKDTree

from abs.reassembly.volume import Volume

__all__ = ["Phantom", "make_phantom", "random_directions", "mesh_distance"]


@dataclass(frozen=True)
class Phantom:
    """A phantom volume and its truth, all in the volume frame (mm, see :mod:`.volume`).

    Attributes
    ----------
    volume : Volume
        The simulated scan (``uint16``).
    glass_centre_mm : np.ndarray
        ``(3,)`` centre of the glass sphere.
    glass_radius_mm : float
        Its radius.
    marker_centres_mm : np.ndarray
        ``(n, 3)`` marker centres.
    marker_radii_mm : np.ndarray
        ``(n,)`` marker radii.
    glass_mesh_mm : trimesh.Trimesh or None
        The true glass surface when the glass is a mesh (then ``glass_radius_mm`` is ``nan`` and
        ``glass_centre_mm`` its bounding-box centre).
    """

    volume: Volume
    glass_centre_mm: np.ndarray
    glass_radius_mm: float
    marker_centres_mm: np.ndarray
    marker_radii_mm: np.ndarray
    glass_mesh_mm: trimesh.Trimesh | None = None

    def glass_distance_mm(self, points_mm: np.ndarray) -> np.ndarray:
        """Unsigned distance of points (mm) from the true glass surface, mm."""
        if self.glass_mesh_mm is not None:
            return np.abs(mesh_distance(self.glass_mesh_mm, points_mm))
        d = np.linalg.norm(np.asarray(points_mm) - self.glass_centre_mm, axis=-1)
        return np.abs(d - self.glass_radius_mm)


def random_directions(n: int, rng: np.random.Generator, min_angle: float = 0.5) -> np.ndarray:
    """``n`` random unit vectors at least ``min_angle`` radians apart (markers glued by hand:
    irregular, so that their pairwise distances tell them apart)."""
    out: list[np.ndarray] = []
    for _ in range(100000):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        if all(np.arccos(np.clip(d @ e, -1, 1)) >= min_angle for e in out):
            out.append(d)
            if len(out) == n:
                return np.array(out)
    raise ValueError(f"cannot place {n} markers {min_angle} rad apart")


def mesh_distance(mesh: trimesh.Trimesh, points: np.ndarray, k: int = 8,
                  chunk: int = 100_000) -> np.ndarray:
    """Signed distance of points from a closed mesh (positive outside), exact where the nearest
    triangle is among the ``k`` with the nearest centroids (always, for points nearer the mesh
    than a few of its edge lengths: :func:`make_phantom` subdivides a glass mesh to 1 mm edges).
    The sign is that of the nearest triangle's normal."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tree = cKDTree(mesh.triangles_center)
    tris = np.asarray(mesh.triangles)
    normals = np.asarray(mesh.face_normals)
    k = min(k, len(tris))
    out = np.empty(len(pts))
    for s in range(0, len(pts), chunk):
        p = pts[s:s + chunk]
        _, idx = tree.query(p, k=k)
        idx = idx.reshape(len(p), k)
        q = trimesh.triangles.closest_point(tris[idx.ravel()], np.repeat(p, k, axis=0)).reshape(len(p), k, 3)
        d = np.linalg.norm(q - p[:, None], axis=2)
        best = d.argmin(axis=1)
        rows = np.arange(len(p))
        q_best = q[rows, best]
        side = np.einsum("ij,ij->i", p - q_best, normals[idx[rows, best]])
        out[s:s + chunk] = np.where(side < 0, -1.0, 1.0) * d[rows, best]
    return out


def _mesh_occupancy(mesh: trimesh.Trimesh, shape: tuple[int, int, int], voxel: float) -> np.ndarray:
    """Partial-volume occupancy ``[k, j, i]`` of a closed mesh (mm, volume frame): exact signed
    distances in a band of voxels around the surface, inside or outside elsewhere from the
    connected pieces of the rest of the grid."""
    samples, _ = trimesh.sample.sample_surface(mesh, int(8 * mesh.area / voxel ** 2) + 1000, seed=0)
    samples = np.concatenate([samples, mesh.vertices])
    ijk = np.clip(np.rint(samples / voxel).astype(int), 0, np.array(shape[::-1]) - 1)
    band = np.zeros(shape, dtype=bool)
    band[ijk[:, 2], ijk[:, 1], ijk[:, 0]] = True
    band = ndimage.binary_dilation(band, iterations=2)
    kk, jj, ii = np.nonzero(band)
    d = mesh_distance(mesh, np.stack([ii, jj, kk], axis=1) * voxel)
    occ = np.zeros(shape, dtype=np.float32)
    occ[kk, jj, ii] = np.clip(0.5 - d / voxel, 0, 1)
    labels, _ = ndimage.label(~band)
    border = np.unique(np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(),
                                       labels[:, :, [0, -1]].ravel()]))
    occ[(labels > 0) & ~np.isin(labels, border)] = 1.0
    return occ


def _surface_markers(mesh: trimesh.Trimesh, radii: np.ndarray, embed: float, min_gap: float,
                     rng: np.random.Generator) -> np.ndarray:
    """Marker centres ``embed * r`` off random surface points, at least ``min_gap`` apart and
    clear of every other sheet of the surface (a thin wall's other side)."""
    out: list[np.ndarray] = []
    for _ in range(100000):
        r = radii[len(out)]
        p, f = trimesh.sample.sample_surface(mesh, 1, seed=int(rng.integers(2 ** 31)))
        c = p[0] + embed * r * mesh.face_normals[f[0]]
        if any(np.linalg.norm(c - e) < min_gap for e in out):
            continue
        if abs(mesh_distance(mesh, c[None])[0] - embed * r) > 1e-6:
            continue  # another part of the surface lies nearer than the one it is glued on
        out.append(c)
        if len(out) == len(radii):
            return np.array(out)
    raise ValueError(f"cannot place {len(radii)} markers {min_gap} mm apart")


def make_phantom(voxel_mm: float = 0.5, *, glass_radius_mm: float = 8.0, n_markers: int = 6,
                 marker_radius_mm: float | tuple[float, float] = 1.5, embed: float = 0.5,
                 air: float = 200.0, glass: float = 1000.0, marker: float = 4000.0,
                 noise_sd: float = 40.0, streak: float = 2500.0, streak_length: float = 0.6,
                 streak_width: float = 0.35, margin_mm: float = 2.0, seed: int = 0,
                 glass_mesh_mm: trimesh.Trimesh | None = None, marker_gap_mm: float = 10.0) -> Phantom:
    """Simulate a CT scan of a glass sphere (or of a glass mesh) with markers.

    Parameters
    ----------
    voxel_mm : float
        Cubic voxel size, mm.
    glass_radius_mm : float
        Radius of the glass sphere, mm.
    n_markers : int
        Number of markers (at random on the sphere, at least 0.5 rad apart).
    marker_radius_mm : float or (low, high)
        Marker radius, mm, or a range drawn from uniformly per marker.
    embed : float
        Marker centre at ``glass_radius + embed * r`` from the glass centre (0: half sunk into
        the glass, 1: touching it).
    air, glass, marker : float
        Grey values: air level, glass and marker densities above it.
    noise_sd : float
        Standard deviation of the Gaussian density noise (grey values).
    streak : float
        Peak of the streaks (grey values) added along +-x next to each marker.
    streak_length, streak_width : float
        Decay length along x and Gaussian width across, in marker radii.
    margin_mm : float
        Air around the object, mm.
    seed : int
        Random seed (marker layout, radii, noise).
    glass_mesh_mm : trimesh.Trimesh, optional
        A closed glass mesh in mm (e.g. ``scenes/default/bowl.ply`` scaled by 1000) instead of
        the sphere; it is moved into the volume (its bounding box centred). Markers go on random
        surface points, at least ``marker_gap_mm`` apart.
    """
    rng = np.random.default_rng(seed)
    if np.ndim(marker_radius_mm) == 0:
        radii = np.full(n_markers, float(marker_radius_mm))
    else:
        lo, hi = marker_radius_mm
        radii = rng.uniform(lo, hi, n_markers)
    pad = (1 + embed) * radii.max() + margin_mm
    mesh_occ = None
    if glass_mesh_mm is None:
        n = int(np.ceil(2 * (glass_radius_mm + pad) / voxel_mm)) + 1
        shape = (n, n, n)
        centre = np.full(3, (n - 1) * voxel_mm / 2)
        dirs = random_directions(n_markers, rng)
        centres = centre + dirs * (glass_radius_mm + embed * radii)[:, None]
    else:
        lo, hi = glass_mesh_mm.bounds
        nx, ny, nz = (np.ceil((hi - lo + 2 * pad) / voxel_mm) + 1).astype(int)
        shape = (int(nz), int(ny), int(nx))
        centre = (np.array([nx, ny, nz]) - 1) * voxel_mm / 2
        # Same surface, edges of at most 1 mm, so that mesh_distance's nearest centroids hold the
        # nearest triangle.
        v, f = trimesh.remesh.subdivide_to_size(glass_mesh_mm.vertices + (centre - 0.5 * (lo + hi)),
                                                glass_mesh_mm.faces, 1.0, max_iter=20)
        glass_mesh_mm = trimesh.Trimesh(v, f, process=True)
        glass_radius_mm = float("nan")
        centres = _surface_markers(glass_mesh_mm, radii, embed, marker_gap_mm, rng)
        mesh_occ = _mesh_occupancy(glass_mesh_mm, shape, voxel_mm)

    x = (np.arange(shape[2]) * voxel_mm)[None, None, :]
    y = (np.arange(shape[1]) * voxel_mm)[None, :, None]
    data = np.empty(shape, dtype=np.uint16)
    for k in range(shape[0]):  # slab by slab: a 0.2 mm volume of a large object does not fit as float64
        z = k * voxel_mm
        if mesh_occ is None:
            d_glass = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2) - glass_radius_mm
            occ_glass = np.clip(0.5 - d_glass / voxel_mm, 0, 1)
        else:
            occ_glass = np.broadcast_to(mesh_occ[k][None], (1, shape[1], shape[2]))
        occ_marker = np.zeros(occ_glass.shape)
        streaks = np.zeros(occ_glass.shape)
        for c, r in zip(centres, radii):
            if abs(z - c[2]) > max(3 * r, r + voxel_mm):  # marker and streaks are nil beyond
                continue
            d_m = np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) - r
            occ_marker = np.maximum(occ_marker, np.clip(0.5 - d_m / voxel_mm, 0, 1))
            across = (y - c[1]) ** 2 + (z - c[2]) ** 2
            along = np.maximum(np.abs(x - c[0]) - r, 0)
            streaks = streaks + streak * np.exp(-across / (2 * (streak_width * r) ** 2)
                                                - along / (streak_length * r))
        value = (air + glass * occ_glass * (1 - occ_marker) + marker * occ_marker
                 + streaks * (1 - occ_marker) + rng.normal(0, noise_sd, occ_glass.shape))
        data[k] = np.clip(np.rint(value), 0, 65535).astype(np.uint16)
    # Volume frame: (x, y, z) = (i, j, k) * voxel; the arrays above were laid out [k, j, i].
    return Phantom(Volume(data, voxel_mm), centre, float(glass_radius_mm), centres, radii, glass_mesh_mm)
