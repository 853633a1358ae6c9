"""A sun's highlight: the coating roughness that shapes it.

The fitted light (:mod:`~abs.resynthesis.lighting`) is smooth, so the sharp highlight of a sun is
left out of the material fit (:func:`~abs.resynthesis.method.fit_mask`). Without it the coating's
roughness is a coin toss: the remaining residuals of the candidates lie within a few per cent of
each other, because the smooth light and the reflectance absorb the difference
(docs/editing.md, Limits). The highlight is where the roughness shows: a sun is nearly a point,
so the highlight's spread is the coating's lobe seen through the surface's curvature.

Here a sun is fitted to what the smooth model leaves of the highlight, once per candidate
roughness, and the candidate whose lobe reproduces it best wins:

- the residual ``photo - current``, ``current`` the fitted plastic of that roughness rendered
  under the fitted light, is compared over the object's inner pixels with ``a * S``, ``S`` the
  bare coating (reflectance 0, the same roughness) lit by a directional sun of unit irradiance
  from ``w``, and ``a >= 0`` the sun's irradiance per colour channel (least squares, closed
  form). The coating alone, because the sun's diffuse light is already in the residual's smooth
  part (the smooth light absorbed it). ``S`` is evaluated (one BSDF evaluation and shadow ray
  per sub-pixel hit), not path traced: a path-traced sun of a few texels sparkles, and the
  sparkles decided the comparison (``abs.resynthesis.method._coating_under_sun``). The sun is a
  direction, the real one half a degree wide: a finer lobe than the true one may fit a little
  better, which the candidates' spacing (factors of 2) leaves room for;
- ``w`` starts at the mirror direction of the highlight's brightest pixel on the inflated mesh
  and is refined on 3 x 3 grids of tangent offsets, halving the step
  (:data:`DIRECTION_STEPS_RAD`), each centred on the best so far.

On ``benchmarks/material_edit.py``'s blue ellipsoid (GGX 0.05, the sun of pedestrian_overpass;
photographs at 256 spp) this chose 0.05 on three seeds out of 0.05 / 0.1 / 0.2 (highlight RMSE
0.103 / 0.110 / 0.341, 0.094 / 0.100 / 0.273 and 0.104 / 0.107 / 0.304: 0.1 close behind), where
the residual rule chose 0.05, 0.2 and 0.2; the fitted sun lay 6-7 degrees from the map's, of its
colour (1 : 0.51 : 0.10), 1.1 to 1.4 times its irradiance. With the benchmark's photographs at
64 spp one seed of three chose 0.1 (0.115 / 0.063 / 0.248): the photograph's highlight was itself
sparkling Monte-Carlo noise. An earlier form of this test (2026-11-27, a blob sun on the mesh
inflated by the distance to the outline, a capsule for that ellipse) had preferred 0.1: the
highlight's spread is curvature and roughness together, so this needs the shape Poisson's
inflation gives (:mod:`~abs.resynthesis.inflation`).

The fitted sun also lights both renderings of a gloss edit (:func:`abs.resynthesis.method.
edit_fitted`): in ``photo + new - current`` its diffuse light cancels and its highlight takes the
new roughness's shape. Edits that replace the surface are rendered without it, since the smooth
light already holds its diffuse part.

Directions are world directions of abs's lat-long convention
(:func:`abs.editing.environment.latlong_directions`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["DIRECTION_STEPS_RAD", "MIN_HIGHLIGHT_PIXELS", "SunFit", "sun_map",
           "mirror_direction", "fit_sun"]

DIRECTION_STEPS_RAD = (0.08, 0.04, 0.02, 0.01)
"""Steps of the sun direction's refinement (3 x 3 offsets each, radians): it reaches 0.15 rad
(8.6 degrees) from the mirror direction, which the inflated mesh's normals are within."""
MIN_HIGHLIGHT_PIXELS = 4
"""Fewer highlight pixels than this are not a sun's highlight to learn a roughness from."""


@dataclass(frozen=True)
class SunFit:
    """A sun fitted to a highlight.

    Attributes
    ----------
    direction : np.ndarray
        ``(3,)`` unit world direction towards the sun.
    irradiance : np.ndarray
        ``(3,)`` its irradiance per channel (radiance integrated over its solid angle), in the
        map's radiance units times steradians (:func:`sun_map`).
    rmse : float
        Of ``residual - irradiance * rendering`` over the compared pixels.
    """

    direction: np.ndarray
    irradiance: np.ndarray
    rmse: float


def sun_map(height: int, direction: np.ndarray) -> np.ndarray:
    """A lat-long map ``(height, 2 height, 3)`` holding one sun of unit irradiance in ``direction``.

    The sun is splatted bilinearly onto the four texels around ``direction`` (so that the
    highlight moves continuously with the direction, not in texel steps), each texel's radiance
    its weight over its solid angle: radiance integrated over the sphere is 1 whatever the map's
    size, so a sun fitted on one map goes into another unchanged. Everything else is black.
    """
    x, y, z = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    width = 2 * height
    # Inverse of latlong_directions: column centres at phi = 2 pi (i + 0.5) / W, rows at
    # theta = pi j / (H - 1), d = (sin theta sin phi, cos theta, -sin theta cos phi).
    col = (np.arctan2(x, -z) % (2 * np.pi)) / (2 * np.pi) * width - 0.5
    row = np.arccos(np.clip(y, -1.0, 1.0)) / np.pi * (height - 1)
    latlong = np.zeros((height, width, 3), np.float32)
    c0, r0 = int(np.floor(col)), int(np.floor(row))
    fc, fr = col - c0, row - r0
    d_theta = np.pi / (height - 1)
    for dr, wr in ((0, 1 - fr), (1, fr)):
        for dc, wc in ((0, 1 - fc), (1, fc)):
            r = min(r0 + dr, height - 1)
            # The solid angle a texel carries under the renderer's bilinear lookup (rows at
            # theta = pi j / (H - 1), columns 2 pi / W apart): its tent integrated against
            # sin(theta) dtheta dphi; at a pole only the inner half of the tent exists.
            if r in (0, height - 1):
                weight = 1.0 - np.sin(d_theta) / d_theta
            else:
                weight = 2.0 * (1.0 - np.cos(d_theta)) / d_theta * np.sin(np.pi * r / (height - 1))
            latlong[r, (c0 + dc) % width] += wr * wc / (2.0 * np.pi / width * weight)
    return latlong


def mirror_direction(vertices: np.ndarray, faces: np.ndarray, K: np.ndarray, R: np.ndarray,
                     pixel: tuple[int, int]) -> np.ndarray:
    """World direction that the mesh mirrors into the camera at ``pixel`` ``(row, col)``.

    The normal is the mean vertex normal of the four camera-facing vertices that project nearest
    to the pixel's centre (the inflated mesh's front sheet has a vertex at every pixel corner).

    Parameters
    ----------
    vertices, faces : np.ndarray
        The mesh in the camera frame (x right, y down, z forward), the camera at the origin.
    K, R : np.ndarray
        The camera's intrinsics and world-to-camera rotation (``x_cam = R X + t``).
    """
    import trimesh

    normals = trimesh.Trimesh(vertices, faces, process=False).vertex_normals
    facing = np.einsum("ij,ij->i", normals, vertices) < 0
    p = vertices[facing] @ K.T
    uv = p[:, :2] / p[:, 2:3]
    near = np.argsort(np.hypot(uv[:, 0] - pixel[1], uv[:, 1] - pixel[0]))[:4]
    n = normals[facing][near].mean(axis=0)
    n /= np.linalg.norm(n)
    ray = np.linalg.solve(K, np.array([pixel[1], pixel[0], 1.0]))
    ray /= np.linalg.norm(ray)
    towards_sun = ray - 2.0 * (ray @ n) * n  # the reflected view ray: where the light came from
    return R.T @ towards_sun


def _tangents(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(d, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


def fit_sun(residual: np.ndarray, render: Callable[[np.ndarray], np.ndarray],
            start: np.ndarray) -> SunFit:
    """The sun that best explains ``residual`` (module docstring).

    Parameters
    ----------
    residual : np.ndarray
        ``(n, 3)`` what the smooth model leaves of the photograph over the compared pixels.
    render : callable
        ``render(direction) -> (n, 3)``: the same pixels lit by a sun of unit irradiance from
        world ``direction`` (the irradiance :func:`sun_map` holds, so that the fitted value goes
        into a map unchanged).
    start : np.ndarray
        ``(3,)`` the first direction (:func:`mirror_direction`).
    """
    def explain(direction: np.ndarray) -> SunFit:
        image = render(direction)
        irradiance = np.maximum((image * residual).sum(axis=0)
                                / np.maximum((image * image).sum(axis=0), 1e-20), 0.0)
        rmse = float(np.sqrt(np.mean((residual - irradiance * image) ** 2)))
        return SunFit(direction, irradiance, rmse)

    best = explain(start / np.linalg.norm(start))
    for step in DIRECTION_STEPS_RAD:
        e1, e2 = _tangents(best.direction)
        centre = best
        for i in (-1, 0, 1):
            for j in (-1, 0, 1):
                if i == j == 0:
                    continue
                d = centre.direction + step * (i * e1 + j * e2)
                trial = explain(d / np.linalg.norm(d))
                if trial.rmse < best.rmse:
                    best = trial
    return best
