"""The environment of the edit: the photograph's own background where the camera sees it.

Inside the camera's field of view the filled background (:func:`abs.editing.holes.fill_background`,
the baseline's hole filling) *is* the light arriving from those directions, so it is painted into
the lat-long map exactly, by projecting every texel's direction into the photograph: a textured
backdrop at infinity, which is what a refracting object shows of a distant scene. Outside the
field of view nothing was photographed; there the baseline's estimate (the paper's mirrored
hemisphere, :func:`abs.editing.environment.environment_from_photograph`) stands, and the fit
scales it (:mod:`abs.resynthesis.method`).
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.editing.environment import latlong_directions, world_to_camera

__all__ = ["frustum_texels", "environment_with_backdrop"]


def _project(K: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = world_to_camera(latlong_directions(height, width))
    z = d[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        p = np.einsum("ij,...j->...i", K, d / z[..., None])
    return p[..., 0], p[..., 1], z


def frustum_texels(K: np.ndarray, shape: tuple[int, int], map_height: int) -> np.ndarray:
    """Texels of a lat-long map (abs's convention, camera along world +z) that the camera sees.

    Parameters
    ----------
    K : np.ndarray
        ``(3, 3)`` intrinsics, pixels.
    shape : tuple of int
        ``(height, width)`` of the photograph.
    map_height : int
        Height of the map (its width is twice that).

    Returns
    -------
    np.ndarray
        ``(map_height, 2 map_height)`` bool.
    """
    h, w = shape
    x, y, z = _project(K, map_height, 2 * map_height)
    return (z > 0) & (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)


def environment_with_backdrop(environment: np.ndarray, background: np.ndarray, K: np.ndarray,
                              map_height: int) -> tuple[np.ndarray, np.ndarray]:
    """The baseline's map resampled to ``map_height`` with the background painted in.

    Parameters
    ----------
    environment : np.ndarray
        ``(H, 2H, 3)`` the baseline's lat-long map (linear radiance).
    background : np.ndarray
        ``(height, width, 3)`` the photograph with the object's hole filled.
    K : np.ndarray
        ``(3, 3)`` the photograph's intrinsics, pixels (camera at the origin along world +z).
    map_height : int
        Height of the result; fine enough that the backdrop keeps the photograph's detail
        (a texel per pixel or finer across the field of view).

    Returns
    -------
    latlong : np.ndarray
        ``(map_height, 2 map_height, 3)`` float32.
    seen : np.ndarray
        ``(map_height, 2 map_height)`` bool, the texels painted from the background.
    """
    out = cv2.resize(np.ascontiguousarray(environment, np.float32), (2 * map_height, map_height),
                     interpolation=cv2.INTER_LINEAR)
    h, w = background.shape[:2]
    x, y, _ = _project(K, map_height, 2 * map_height)
    seen = frustum_texels(K, (h, w), map_height)
    painted = cv2.remap(np.ascontiguousarray(background, np.float32),
                        np.where(seen, x, -1).astype(np.float32),
                        np.where(seen, y, -1).astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
    out[seen] = painted[seen]
    return out, seen
