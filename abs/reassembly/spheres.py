"""Several spheres fitted to points by sequential RANSAC (the markers on a CT marker mesh).

Each round draws minimal samples of 4 nearby points (within a log-uniform radius), fits the sphere through them, keeps the
hypothesis with most inliers (points within ``tol`` of its surface, radius in range), refines
it by geometric least squares on its inliers, then removes every point within
``remove_factor * r`` of its centre (its surface and any streak tail attached to it) and starts
the next round. Rounds stop when the best sphere has fewer than ``min_inliers`` inliers.

A hypothesis must also cover its sphere: at least ``min_coverage * density * 4 pi r^2`` inliers
(``density``: points per unit area, about one per voxel face for a marching-cubes mesh), so that
a large sphere through a small patch of a flat or gently curved surface is not taken for a
marker; and its inliers must reach at least ``min_directions`` of the direction cells around its
centre (about 3 expected points per cell), so that a small sphere through the rounded edge or
corner of a dense block, which its inliers meet in a few rings, is not either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["SphereFit", "fit_sphere", "ransac_spheres", "directions_seen"]


def _cells(n: int) -> np.ndarray:
    """``n`` evenly spread unit vectors (a Fibonacci lattice): direction cells."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    return np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)


def directions_seen(points: np.ndarray, centre: np.ndarray, cells: int = 12) -> float:
    """Fraction of ``cells`` direction cells around ``centre`` that hold at least one point."""
    d = np.asarray(points, dtype=np.float64) - centre
    if not len(d):
        return 0.0
    return len(np.unique(np.argmax(d @ _cells(cells).T, axis=1))) / cells


def _covers(points: np.ndarray, centre: np.ndarray, radius: float, density: float | None,
            min_coverage: float, min_directions: float) -> bool:
    """Enough inliers for the sphere's area, spread over enough direction cells (about 3
    expected points per cell, 12 to 96 cells)."""
    if density is None:
        return directions_seen(points, centre, 12) >= min_directions
    expected = density * 4 * np.pi * radius * radius
    if len(points) < min_coverage * expected:
        return False
    cells = int(np.clip(expected // 3, 12, 96))
    return directions_seen(points, centre, cells) >= min_directions


@dataclass(frozen=True)
class SphereFit:
    """One fitted sphere.

    Attributes
    ----------
    centre : np.ndarray
        ``(3,)`` centre, in the points' unit (mm for a CT mesh).
    radius : float
        Radius, same unit.
    inliers : int
        Points within the tolerance of its surface.
    rms : float
        RMS distance of the inliers from the surface.
    """

    centre: np.ndarray
    radius: float
    inliers: int
    rms: float



def _algebraic(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares sphere from ``|p|^2 = 2 c.p + (r^2 - |c|^2)`` (exact through 4 points)."""
    A = np.c_[2 * points, np.ones(len(points))]
    b = np.sum(points * points, axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = sol[:3]
    r2 = sol[3] + c @ c
    return c, float(np.sqrt(r2)) if r2 > 0 else float("nan")


def fit_sphere(points: np.ndarray, iterations: int = 20) -> tuple[np.ndarray, float, float]:
    """Geometric least-squares sphere (Gauss-Newton from the algebraic fit).

    Returns ``(centre, radius, rms)``.
    """
    p = np.asarray(points, dtype=np.float64)
    c, r = _algebraic(p)
    for _ in range(iterations):
        d = p - c
        n = np.linalg.norm(d, axis=1)
        n = np.where(n > 0, n, 1e-12)
        res = n - r
        J = np.c_[-d / n[:, None], -np.ones(len(p))]
        step, *_ = np.linalg.lstsq(J, -res, rcond=None)
        c = c + step[:3]
        r = r + step[3]
        if np.linalg.norm(step) < 1e-10 * max(1.0, abs(r)):
            break
    res = np.linalg.norm(p - c, axis=1) - r
    return c, float(r), float(np.sqrt(np.mean(res ** 2)))


def _ransac_one(points: np.ndarray, tree: cKDTree, alive: np.ndarray, tol: float,
                r_min: float, r_max: float, trials: int, rng: np.random.Generator,
                density: float | None, min_coverage: float, min_directions: float):
    idx = np.flatnonzero(alive)
    best = (0, None, None)
    for _ in range(trials):
        seed = idx[rng.integers(len(idx))]
        # neighbours within 2 rho, rho log-uniform in [r_min, r_max]: a small sphere among other
        # surfaces is sampled as often as a large one
        rho = r_min * (r_max / r_min) ** rng.random()
        near = [i for i in tree.query_ball_point(points[seed], 2 * rho) if alive[i] and i != seed]
        if len(near) < 3:
            continue
        sample = np.r_[seed, rng.choice(near, 3, replace=False)]
        c, r = _algebraic(points[sample])
        if not (np.isfinite(r) and r_min <= r <= r_max):
            continue
        cand = tree.query_ball_point(c, r + tol)
        cand = np.asarray([i for i in cand if alive[i]], dtype=int)
        if len(cand) <= best[0]:
            continue
        inl = cand[np.abs(np.linalg.norm(points[cand] - c, axis=1) - r) < tol]
        if len(inl) > best[0] and _covers(points[inl], c, r, density, min_coverage, min_directions):
            best = (len(inl), c, r)
    return best


def ransac_spheres(points: np.ndarray, *, tol: float, r_min: float, r_max: float,
                   min_inliers: int, max_spheres: int = 64, trials: int = 300,
                   remove_factor: float = 1.5, density: float | None = None,
                   min_coverage: float = 0.6, min_directions: float = 0.6,
                   seed: int = 0) -> list[SphereFit]:
    """Fit spheres to points one after another (see the module docstring).

    Parameters
    ----------
    points : (n, 3) array
        Points on the spheres' surfaces (and outliers).
    tol : float
        Inlier distance from a sphere's surface (about half a voxel for a CT mesh).
    r_min, r_max : float
        Accepted radii.
    min_inliers : int
        A sphere with fewer inliers ends the search.
    max_spheres : int
        At most this many spheres.
    trials : int
        Minimal samples drawn per sphere.
    remove_factor : float
        Points within ``remove_factor * r`` of a found sphere's centre are removed before the
        next round.
    density : float, optional
        Points per unit area on a fully seen sphere (``1 / voxel**2`` for a CT mesh); with
        ``min_coverage``, the inliers a sphere of radius r needs. ``None``: no coverage test.
    min_coverage : float
        Fraction of ``density * 4 pi r^2`` a sphere's inliers must reach.
    min_directions : float
        Fraction of the direction cells a sphere's inliers must reach (0: no test).
    seed : int
        Random seed.

    Returns
    -------
    list of SphereFit
        In the order found (most inliers first, roughly).
    """
    points = np.asarray(points, dtype=np.float64)
    rng = np.random.default_rng(seed)
    tree = cKDTree(points)
    alive = np.ones(len(points), dtype=bool)
    found: list[SphereFit] = []
    while len(found) < max_spheres and alive.sum() >= max(4, min_inliers):
        count, c, r = _ransac_one(points, tree, alive, tol, r_min, r_max, trials, rng, density,
                                  min_coverage, min_directions)
        if count < min_inliers:
            break
        for _ in range(3):  # refine on the inliers, then re-collect them
            dist = np.abs(np.linalg.norm(points - c, axis=1) - r)
            inl = alive & (dist < tol)
            c, r, rms = fit_sphere(points[inl])
        dist = np.abs(np.linalg.norm(points - c, axis=1) - r)
        inl = alive & (dist < tol)
        alive &= np.linalg.norm(points - c, axis=1) > remove_factor * r
        if (not (r_min <= r <= r_max) or inl.sum() < min_inliers
                or not _covers(points[inl], c, r, density, min_coverage, min_directions)):
            continue  # the refined sphere left the accepted range: its points are gone, go on
        found.append(SphereFit(c, float(r), int(inl.sum()), float(rms)))
    return found
