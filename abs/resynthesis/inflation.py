"""A closed mesh from the object's silhouette: the mask inflated into a round solid.

One photograph fixes the object's outline but not its depth. The analysis-by-synthesis edit
(:mod:`abs.resynthesis.method`) starts from the roundest solid with that outline: every point of
the mask is lifted towards the camera by ``h = sqrt(4 phi)``, where ``phi`` solves Poisson's
equation ``-laplacian(phi) = 1`` inside the outline with ``phi = 0`` on it, and mirrored away from
the camera. For a disc of radius ``R``, ``phi = (R^2 - r^2) / 4`` and the solid is the sphere; for
an ellipse of semi-axes ``a, b``, ``phi`` is the quadratic ``(1 - x^2/a^2 - y^2/b^2) a^2 b^2 /
(2 (a^2 + b^2))`` and the solid is an ellipsoid of depth semi-axis ``a b sqrt(2 / (a^2 + b^2))``
(between ``a`` and ``b``): the round solids a photographed blob is most often the outline of.
Lifting by the distance ``d`` to the outline instead, ``sqrt(d (2 R_in - d))`` (the usual
inflation of sketch-based modelling, Igarashi et al. 1999; abs's until 2026-11-28), gives the same
sphere for a disc but a capsule for an ellipse: flat along the long axis, as deep as the short
one. On ``benchmarks/material_edit.py``'s ellipsoid (semi-axes 1.3 : 0.8 across the view, 1.0
deep) that was 0.8 deep where the Poisson solid is 0.96 (pixel heights: 1.9 pixel rms from the
true ellipsoid's, now 0.1). Square roots of Poisson solutions as inflation: e.g. Johnston's
"Lumo" (2002) and the "Monster Mash" line of sketch-based modelling.

``phi`` is solved by the method of fundamental solutions: ``phi = -|x - c|^2 / 4 + w`` with ``w``
harmonic, a sum of ``log |x - s_k|`` over sources ``s_k`` placed outside the outline (along its
outward normals) plus a constant, fitted by least squares to ``w = |x - c|^2 / 4`` at dense points
of the outline. This keeps ``phi`` near 0 on the smoothed sub-pixel outline (below: a least-squares
fit, within a small fraction of a pixel in the outline's position), which the steep profile near
the outline needs, and ``phi`` is smooth everywhere inside, several components and holes included
(holes below :data:`SMALL_HOLE_FRACTION` of the area are filled first: a matte's pinholes).

Two details decide whether the inflated sphere shades like a sphere (measured on
``benchmarks/material_edit.py``'s photograph of a sphere, rendered under the true light with the
true material: the low-passed residual against the photograph was 0.050 with pixel-grid distances
lifted along each pixel's ray, 0.012 as below, 0.010 for the true sphere's mesh):

- **The outline is smooth and sub-pixel**, not the mask's staircase of pixel corners. Near the
  outline the slope ``dh/dd`` grows without bound, so a staircase (half a pixel) becomes stripes
  of wrong normals. The outline is the mask's 0.5 iso-line (marching squares,
  :func:`skimage.measure.find_contours`) smoothed along its length by a Gaussian of
  ``outline_sigma_px``.
- **Points are lifted along the object's central ray**, not along their own pixel rays. The
  outline's corners lie in the plane through the point ``distance`` ahead on the ray through the
  mask's centroid, perpendicular to that ray, where their pixel rays meet it (so the outline
  projects exactly onto the mask's); each inner corner moves by ``h`` along the central ray. A
  disc then gives an exact sphere about that point. Lifting along the pixel rays instead squashes
  it (a point half way out ends 5 % inside the sphere for an object of 16 degrees), which bends
  every normal. The sphere's own silhouette is its tangent cone, a factor ``1/cos`` of its half
  angle wider than the mask (1 % at 8 degrees): left as it is.

Geometry (docs/conventions.md): camera frame, x right, y down, z forward; lengths are metres, depth
``h`` is converted from pixels at the object's distance (``h_m = h_px distance / f``).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["OUTLINE_SIGMA_PX", "SMALL_HOLE_FRACTION", "fill_small_holes", "inflation_heights",
           "inflated_mesh"]

OUTLINE_SIGMA_PX = 2.0
"""Default smoothing of the outline along its length, pixels (a Gaussian's sd)."""

SMALL_HOLE_FRACTION = 0.01
"""Holes in the mask smaller than this fraction of its area are filled before inflating: a matte's
pinholes, not the object's (Poisson's solution vanishes on every outline, so a one-pixel hole
would pull the whole solid down around it)."""

_OUTLINE_SPACING_PX = 0.1  # the smoothed outline resampled this densely: point distance = segment
# distance to within spacing^2 / (8 d), far below a pixel.


def _outline_lines(mask: np.ndarray, sigma_px: float) -> list[np.ndarray]:
    """Dense points on each of the mask's smoothed 0.5 iso-lines (closed, in order), pixel
    coordinates ``(row, col)``."""
    from skimage import measure

    padded = np.pad(np.asarray(mask, float), 1)  # every outline closed
    points = []
    for line in measure.find_contours(padded, 0.5):
        line = line[:-1] - 1.0  # closed: the last point repeats the first; back to mask pixels
        # A Gaussian over a line much shorter than its window would shrink it to a point.
        if sigma_px > 0 and len(line) > 6 * sigma_px:
            # The iso-line's vertices are 0.7-1 pixel apart: a Gaussian over vertices is about
            # one over pixels.
            line = ndimage.gaussian_filter1d(line, sigma_px, axis=0, mode="wrap")
        nxt = np.roll(line, -1, axis=0)
        length = np.linalg.norm(nxt - line, axis=1)
        steps = np.maximum(np.ceil(length / _OUTLINE_SPACING_PX).astype(int), 1)
        t = np.concatenate([np.arange(n) / n for n in steps])
        start = np.repeat(line, steps, axis=0)
        points.append(start + t[:, None] * (np.repeat(nxt, steps, axis=0) - start))
    return points


def _outward_normals(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Unit normals of one closed outline's consecutive ``points`` ``(row, col)``, pointing out
    of ``mask``."""
    tangent = 0.5 * (np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0))
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    # The side where the signed distance to the mask grows is outside.
    m = np.asarray(mask, bool)
    signed = ndimage.distance_transform_edt(~m) - ndimage.distance_transform_edt(m)
    ahead = ndimage.map_coordinates(signed, (points + normal).T, order=1, mode="nearest")
    behind = ndimage.map_coordinates(signed, (points - normal).T, order=1, mode="nearest")
    return np.where((ahead < behind)[:, None], -normal, normal)


def _room_outside(points: np.ndarray, normals: np.ndarray, mask: np.ndarray,
                  limit: float) -> np.ndarray:
    """How far (pixels, at most ``limit``) each point can move along its normal and stay out of
    the mask: half of that is where its source goes (a source inside would be a singularity in
    the solution)."""
    m = np.pad(np.asarray(mask, bool), 1)
    room = np.full(len(points), limit)
    for t in np.arange(1.0, limit + 0.5, 0.5):
        q = np.round(points + t * normals).astype(int) + 1
        q = np.clip(q, 0, np.array(m.shape) - 1)
        hit = m[q[:, 0], q[:, 1]] & (room == limit)
        room[hit] = t
    return room


def fill_small_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with its holes smaller than :data:`SMALL_HOLE_FRACTION` of its area filled."""
    m = np.asarray(mask, bool)
    holes, count = ndimage.label(ndimage.binary_fill_holes(m) & ~m)
    if count == 0:
        return m
    sizes = ndimage.sum(np.ones_like(m), holes, index=np.arange(1, count + 1))
    small = np.flatnonzero(sizes < SMALL_HOLE_FRACTION * m.sum()) + 1
    return m | np.isin(holes, small)


def inflation_heights(mask: np.ndarray, outline_sigma_px: float = OUTLINE_SIGMA_PX) -> np.ndarray:
    """Heights of the pixel corners above the silhouette's plane, pixels.

    Parameters
    ----------
    mask : np.ndarray
        ``(height, width)`` bool, the object.
    outline_sigma_px : float
        Smoothing of the outline along its length, pixels (module docstring); 0 keeps the
        marching-squares polygon.

    Returns
    -------
    np.ndarray
        ``(height + 1, width + 1)`` heights at the pixel corners (corner ``(j, i)`` is the top-left
        corner of pixel ``(j, i)``); 0 on the outline and outside, ``sqrt(4 phi)`` inside, ``phi``
        the solution of ``-laplacian(phi) = 1`` vanishing on the smoothed outline (module
        docstring). Holes smaller than :data:`SMALL_HOLE_FRACTION` of the mask are filled.
    """
    mask = fill_small_holes(mask)
    m = np.pad(mask, 1)
    # A corner is inside when all four pixels around it are in the mask.
    inside = m[:-1, :-1] & m[:-1, 1:] & m[1:, :-1] & m[1:, 1:]
    heights = np.zeros(inside.shape)
    if not inside.any():
        return heights
    lines = _outline_lines(mask, outline_sigma_px)  # every 0.1 pixel
    outline = np.concatenate(lines)
    # About a source per pixel of outline (a few hundred at most: the solution is smooth), shared
    # among the outlines by length; four collocation points per source.
    n_total = int(np.clip(len(outline) * _OUTLINE_SPACING_PX, 32, 400))
    size = np.sqrt(np.count_nonzero(mask) / np.pi)  # the equivalent disc's radius, pixels
    sources, collocation = [], []
    for line in lines:
        n = max(4, round(n_total * len(line) / len(outline)))
        sites = line[np.linspace(0, len(line), n, endpoint=False).astype(int)]
        normals = _outward_normals(sites, mask)
        sources.append(sites + 0.5 * _room_outside(sites, normals, mask, size)[:, None] * normals)
        collocation.append(line[np.linspace(0, len(line), 4 * n, endpoint=False).astype(int)])
    sources, collocation = np.concatenate(sources), np.concatenate(collocation)
    centre = outline.mean(axis=0)

    def basis(x: np.ndarray) -> np.ndarray:
        r = np.linalg.norm(x[:, None, :] - sources[None], axis=2)
        return np.concatenate([np.log(r), np.ones((len(x), 1))], axis=1)

    def particular(x: np.ndarray) -> np.ndarray:  # -laplacian = 1
        return -np.sum((x - centre) ** 2, axis=1) / 4.0

    A = basis(collocation)
    scale = np.linalg.norm(A, axis=0)  # columns of log r and the constant are of unlike size
    coef = np.linalg.lstsq(A / scale, -particular(collocation), rcond=None)[0] / scale
    jj, ii = np.nonzero(inside)
    corners = np.stack([jj - 0.5, ii - 0.5], axis=1)  # corner (j, i) at (j-0.5, i-0.5)
    phi = np.empty(len(corners))
    for k in range(0, len(corners), 4096):  # bounded memory: corners x sources at a time
        chunk = corners[k:k + 4096]
        phi[k:k + 4096] = particular(chunk) + basis(chunk) @ coef
    heights[jj, ii] = np.sqrt(np.clip(4.0 * phi, 0.0, None))
    return heights


def inflated_mesh(mask: np.ndarray, K: np.ndarray, distance: float, relief: float = 1.0,
                  outline_sigma_px: float = OUTLINE_SIGMA_PX) -> tuple[np.ndarray, np.ndarray]:
    """The inflated silhouette as a closed triangle mesh in the camera frame.

    Parameters
    ----------
    mask : np.ndarray
        ``(height, width)`` bool, the object (not touching the border).
    K : np.ndarray
        ``(3, 3)`` intrinsics of the photograph, pixels.
    distance : float
        Distance of the silhouette's plane along the central ray (through the mask's
        centroid), metres.
    relief : float
        Multiplier of the heights (1: round; a sphere for a disc).
    outline_sigma_px : float
        Smoothing of the outline, pixels (:func:`inflation_heights`).

    Returns
    -------
    vertices : np.ndarray
        ``(n, 3)`` float64, camera frame (x right, y down, z forward), metres.
    faces : np.ndarray
        ``(m, 3)`` int64, counter-clockwise seen from outside (normals point out).
    """
    pm = fill_small_holes(mask)  # the solid is whole there; the matte still composites
    h_px = inflation_heights(pm, outline_sigma_px) * relief
    rows, cols = h_px.shape
    # Corner (j, i) sits at pixel coordinates (i - 0.5, j - 0.5).
    u, v = np.meshgrid(np.arange(cols) - 0.5, np.arange(rows) - 0.5)
    rays = np.linalg.solve(K, np.stack([u.ravel(), v.ravel(), np.ones(u.size)]))  # z = 1
    jj, ii = np.nonzero(pm)
    central = np.linalg.solve(K, np.array([ii.mean(), jj.mean(), 1.0]))
    central /= np.linalg.norm(central)
    plane = rays * (distance / (central @ rays))  # where each corner's ray meets the plane
    focal = float(np.sqrt(K[0, 0] * K[1, 1]))
    h_m = h_px.ravel() * distance / focal
    used = np.zeros((rows, cols), bool)
    used[:-1, :-1] |= pm
    used[:-1, 1:] |= pm
    used[1:, :-1] |= pm
    used[1:, 1:] |= pm
    outline = used & (h_px <= 0)
    index = np.full(rows * cols, -1)
    front = np.flatnonzero(used)
    index[front] = np.arange(front.size)
    back_only = np.flatnonzero(used & ~outline)
    back_index = index.copy()
    back_index[back_only] = front.size + np.arange(back_only.size)  # outline: shared vertices
    verts_front = (plane[:, front] - h_m[front] * central[:, None]).T
    verts_back = (plane[:, back_only] + h_m[back_only] * central[:, None]).T
    a, b = jj * cols + ii, jj * cols + ii + 1  # top-left, top-right corners
    c, d = a + cols, b + cols                  # bottom-left, bottom-right
    # Seen from the camera (outside the front sheet), x right and y down is clockwise on screen
    # for (a, b, d): so (a, d, b) and (a, c, d) face the camera.
    f = np.concatenate([np.stack([index[a], index[d], index[b]], 1),
                        np.stack([index[a], index[c], index[d]], 1)])
    k = np.concatenate([np.stack([back_index[a], back_index[b], back_index[d]], 1),
                        np.stack([back_index[a], back_index[d], back_index[c]], 1)])
    faces = np.concatenate([f, k]).astype(np.int64)
    return np.concatenate([verts_front, verts_back]), faces
