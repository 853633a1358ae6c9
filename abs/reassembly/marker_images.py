"""Synthetic photographs of spherical markers, for tests: exact perspective silhouettes of
spheres (dark discs, slightly elliptical off the axis) on a light, textured, noisy ground.

A pixel's coverage is the share of its ``supersample x supersample`` sub-pixel rays that hit a
sphere (a ray hits a sphere of radius ``r`` at distance ``d`` when its angle from the direction
to the centre is below ``asin(r / d)``). The ground's texture is a smooth random field fixed
relative to the image, so one ``seed`` gives the same picture at any image size. Markers do not
occlude each other (the test layouts keep them apart). Not a renderer: no glass, no shading (a
Mitsuba-rendered truth is a separate matter, docs/reassembly.md).
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.camera.pinhole import project

__all__ = ["marker_image"]


def marker_image(K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int,
                 centres_m: np.ndarray, radius_m: float, *, ground: float = 0.75,
                 marker: float = 0.08, texture: float = 0.1, noise: float = 0.01, seed: int = 0,
                 supersample: int = 4) -> np.ndarray:
    """A ``(height, width)`` float32 grey image of spheres seen by camera ``(K, R, t)``.

    Parameters
    ----------
    K, R, t : np.ndarray
        OpenCV camera (pixels; world-to-camera; metres).
    width, height : int
        Image size, pixels.
    centres_m : (n, 3) array
        Sphere centres, world frame, metres.
    radius_m : float
        Sphere radius, metres.
    ground, marker, texture, noise : float
        Ground level, marker level, texture amplitude and per-pixel noise sd (grey, 0 to 1).
    seed : int
        Texture and noise.
    supersample : int
        Sub-pixel rays per pixel side.
    """
    rng = np.random.default_rng(seed)
    field = cv2.resize(rng.random((12, 16)), (width, height), interpolation=cv2.INTER_CUBIC)
    image = ground + texture * (field - 0.5)
    coverage = np.zeros((height, width))
    K, R, t = (np.asarray(a, np.float64) for a in (K, R, t))
    eye = -R.T @ t.reshape(3)
    Kinv = np.linalg.inv(K)
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    for c in np.asarray(centres_m, np.float64).reshape(-1, 3):
        uv = project(K, R, t, c)
        dist = np.linalg.norm(c - eye)
        if not np.all(np.isfinite(uv)) or dist <= radius_m:
            continue
        half = K[0, 0] * radius_m / np.sqrt(dist ** 2 - radius_m ** 2) * 1.5 + 3
        u0, u1 = max(int(uv[0] - half), 0), min(int(uv[0] + half) + 1, width)
        v0, v1 = max(int(uv[1] - half), 0), min(int(uv[1] + half) + 1, height)
        if u0 >= u1 or v0 >= v1:
            continue
        vv, uu = np.mgrid[v0:v1, u0:u1]
        shape = (v1 - v0, u1 - u0, supersample, supersample)
        su = np.broadcast_to(uu[..., None, None] + offsets[None, None, None, :], shape).reshape(-1)
        sv = np.broadcast_to(vv[..., None, None] + offsets[None, None, :, None], shape).reshape(-1)
        rays = np.column_stack([su, sv, np.ones_like(su)]) @ Kinv.T @ R  # world directions
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        to_c = (c - eye) / dist
        hit = rays @ to_c > np.cos(np.arcsin(radius_m / dist))
        cov = hit.reshape(v1 - v0, u1 - u0, supersample * supersample).mean(axis=2)
        coverage[v0:v1, u0:u1] = np.maximum(coverage[v0:v1, u0:u1], cov)
    image = image * (1 - coverage) + marker * coverage + rng.normal(0, noise, image.shape)
    return np.clip(image, 0, 1).astype(np.float32)
