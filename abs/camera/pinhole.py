"""OpenCV pinhole camera helpers on numpy arrays.

Convention (docs/conventions.md): ``x_cam = R @ X_world + t``; the camera looks along +z, image
x points right and y down; ``[u, v, 1]^T ~ K @ x_cam`` with ``(0, 0)`` the centre of the top-left
pixel. Lengths in metres, focal lengths and pixel coordinates in pixels, angles in radians.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["project", "look_at", "intrinsics_from_fov", "ray_directions", "camera_center"]

ArrayLike = np.ndarray | Sequence[float]


def project(K: ArrayLike, R: ArrayLike, t: ArrayLike, X: ArrayLike) -> np.ndarray:
    """Project world points to pixel coordinates.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Intrinsic matrix, pixels.
    R : array_like, shape (3, 3)
        World-to-camera rotation.
    t : array_like, shape (3,)
        World-to-camera translation, metres.
    X : array_like, shape (N, 3) or (3,)
        World points, metres.

    Returns
    -------
    np.ndarray
        ``(N, 2)`` (or ``(2,)``) pixel coordinates ``(u, v)``, float64. Points on or behind the
        camera plane (``z_cam <= 0``) get NaN, since they have no image.
    """
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (K, R, t))
    X = np.asarray(X, dtype=np.float64)
    x_cam = X @ R.T + t.reshape(3)
    uvw = x_cam @ K.T
    z = uvw[..., 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uvw[..., :2] / z
    return np.where(x_cam[..., 2:3] > 0, uv, np.nan)


def camera_center(R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Camera centre in world coordinates, ``-R^T t`` (metres), shape (3,)."""
    R, t = np.asarray(R, dtype=np.float64), np.asarray(t, dtype=np.float64).reshape(3)
    return -R.T @ t


def look_at(eye: ArrayLike, target: ArrayLike,
            up: ArrayLike = (0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera pose of a camera at ``eye`` looking at ``target``.

    The camera's +z axis points from ``eye`` to ``target``; image y (down) is as close to
    ``-up`` as the viewing direction allows, and image x completes a right-handed frame.

    Parameters
    ----------
    eye, target : array_like, shape (3,)
        Camera centre and point to look at, metres.
    up : array_like, shape (3,)
        World up direction (default +y).

    Returns
    -------
    R : np.ndarray, shape (3, 3)
        World-to-camera rotation (rows: camera x, y, z axes in world coordinates).
    t : np.ndarray, shape (3,)
        World-to-camera translation, ``-R @ eye``.

    Raises
    ------
    ValueError
        If ``eye == target`` or the viewing direction is parallel to ``up``.
    """
    eye, target, up = (np.asarray(a, dtype=np.float64).reshape(3) for a in (eye, target, up))
    forward = target - eye
    norm = np.linalg.norm(forward)
    if norm == 0:
        raise ValueError("look_at: eye and target coincide")
    z = forward / norm
    x = np.cross(z, up)  # right = forward x up, for y-down image coordinates
    if np.linalg.norm(x) < 1e-12 * max(np.linalg.norm(up), 1e-300):
        raise ValueError("look_at: viewing direction is parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ eye


def intrinsics_from_fov(width: int, height: int, fov_y_rad: float) -> np.ndarray:
    """Intrinsic matrix with square pixels and the principal point at the image centre.

    Parameters
    ----------
    width, height : int
        Image size, pixels.
    fov_y_rad : float
        Vertical field of view, radians, spanning the full image height (from the top edge of
        row 0 to the bottom edge of row ``height - 1``).

    Returns
    -------
    np.ndarray
        ``K`` (3, 3), float64, with ``fx = fy = height / (2 tan(fov_y / 2))`` and principal point
        ``((width - 1) / 2, (height - 1) / 2)``, the image centre under the pixel-centre
        convention.
    """
    if not 0 < fov_y_rad < np.pi:
        raise ValueError(f"fov_y_rad must lie in (0, pi), got {fov_y_rad}")
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    f = 0.5 * height / np.tan(0.5 * fov_y_rad)
    return np.array([[f, 0.0, 0.5 * (width - 1)],
                     [0.0, f, 0.5 * (height - 1)],
                     [0.0, 0.0, 1.0]])


def ray_directions(K: ArrayLike, R: ArrayLike, t: ArrayLike,
                   uv: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """World-space rays through pixel positions.

    Parameters
    ----------
    K, R, t : array_like
        Camera as in :func:`project`.
    uv : array_like, shape (N, 2) or (2,)
        Pixel coordinates (pixel-centre convention).

    Returns
    -------
    origins : np.ndarray, shape (N, 3)
        The camera centre for every ray, metres.
    dirs : np.ndarray, shape (N, 3)
        Unit directions in world space, pointing out of the camera (``z_cam > 0``).
    """
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (K, R, t))
    uv = np.asarray(uv, dtype=np.float64)
    pix = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
    d_cam = pix @ np.linalg.inv(K).T
    d_world = d_cam @ R  # R^T d for row vectors
    dirs = d_world / np.linalg.norm(d_world, axis=-1, keepdims=True)
    origins = np.broadcast_to(camera_center(R, t), dirs.shape).copy()
    return origins, dirs
