"""A synthetic CT volume whose truth is known: a glass sphere with small spherical markers glued
on its surface, density noise and beam-hardening streaks along one axis around the markers.

The streaks make glass next to a marker as dense as a marker, and air next to a marker as dense
as glass, so no single threshold separates glass from markers: the marker threshold picks up
streak tails (which the RANSAC sphere fit must reject) and the glass threshold picks up streaks
in air (which carving and keeping the largest piece remove).

Densities are grey values (``uint16``): air ``air``, glass ``air + glass``, markers
``air + marker``. Partial volume is modelled by a linear ramp of the signed distance over one
voxel, exact enough for spheres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.reassembly.volume import Volume

__all__ = ["Phantom", "make_phantom", "random_directions"]


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
    """

    volume: Volume
    glass_centre_mm: np.ndarray
    glass_radius_mm: float
    marker_centres_mm: np.ndarray
    marker_radii_mm: np.ndarray

    def glass_distance_mm(self, points_mm: np.ndarray) -> np.ndarray:
        """Unsigned distance of points (mm) from the true glass surface, mm."""
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


def make_phantom(voxel_mm: float = 0.5, *, glass_radius_mm: float = 8.0, n_markers: int = 6,
                 marker_radius_mm: float | tuple[float, float] = 1.5, embed: float = 0.5,
                 air: float = 200.0, glass: float = 1000.0, marker: float = 4000.0,
                 noise_sd: float = 40.0, streak: float = 2500.0, streak_length: float = 0.6,
                 streak_width: float = 0.35, margin_mm: float = 2.0, seed: int = 0) -> Phantom:
    """Simulate a CT scan of a glass sphere with markers.

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
    """
    rng = np.random.default_rng(seed)
    if np.ndim(marker_radius_mm) == 0:
        radii = np.full(n_markers, float(marker_radius_mm))
    else:
        lo, hi = marker_radius_mm
        radii = rng.uniform(lo, hi, n_markers)
    extent = glass_radius_mm + (1 + embed) * radii.max() + margin_mm
    n = int(np.ceil(2 * extent / voxel_mm)) + 1
    centre = np.full(3, (n - 1) * voxel_mm / 2)
    dirs = random_directions(n_markers, rng)
    centres = centre + dirs * (glass_radius_mm + embed * radii)[:, None]

    coords = np.arange(n) * voxel_mm
    x = coords[None, None, :]
    y = coords[None, :, None]
    data = np.empty((n, n, n), dtype=np.uint16)
    for k in range(n):  # slab by slab: a 0.2 mm volume of a large object does not fit as float64
        z = coords[k]
        d_glass = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2) - glass_radius_mm
        occ_glass = np.clip(0.5 - d_glass / voxel_mm, 0, 1)
        occ_marker = np.zeros_like(occ_glass)
        streaks = np.zeros_like(occ_glass)
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
    return Phantom(Volume(data, voxel_mm), centre, float(glass_radius_mm), centres, radii)
