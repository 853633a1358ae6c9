"""An environment map from the photograph itself (Khan et al. 2006, sec. 6).

The paper takes the largest centred circle of the (object-free) photograph, radius
``r = min(x_c, y_c)``, as the hemisphere *behind* the image plane, the light that travels from
the scene towards the camera. A pixel at normalised offset ``(x_n, y_n) = ((x - x_c) / r,
(y - y_c) / r)`` inside it is the direction

    d = [x_n, y_n, 1 - sqrt(x_n^2 + y_n^2)]   (then normalised),

and the front hemisphere (behind the camera, never seen) is the mirror image of the back one:
``[x, y, -z]`` reads the same pixel as ``[x, y, z]``.

Frames. ``d`` is in abs's camera frame (docs/conventions.md: x right, y down, z forward), so the
centre of the image is the direction straight ahead. The lat-long map is written in abs's
environment convention (Mitsuba's ``envmap``: +y the zenith on the top row, ``u = atan2(x, -z) /
2 pi``, ``v = acos(y) / pi``, column centres at ``u = (i + 0.5) / W``, row centres at ``v = j / (H -
1)``) for a camera that looks along world **+z** with +y up, i.e. ``world = (-x_cam, -y_cam,
z_cam)``. The view direction is then the centre of the map (``u = 0.5``) and the image's right is
right of the centre: the map renders the object as the photograph shows it with an abs camera at
the origin looking along +z (``environment.to_world`` identity).

Pixel coordinates follow docs/conventions.md: ``(0, 0)`` is the centre of the top-left pixel, so
the image centre is ``((W - 1) / 2, (H - 1) / 2)`` and the circle's radius, edge to edge, is
``min(W, H) / 2`` pixels.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["camera_to_world", "world_to_camera", "direction_to_photo_pixel",
           "photo_pixel_to_direction", "latlong_directions", "environment_from_photograph",
           "latlong_lookup", "EnvironmentSampler"]


def camera_to_world(d: np.ndarray) -> np.ndarray:
    """abs camera frame (x right, y down, z forward) to the world of the written map (+y up,
    camera looking along +z): ``(-x, -y, z)``."""
    d = np.asarray(d, np.float64)
    return np.stack([-d[..., 0], -d[..., 1], d[..., 2]], axis=-1)


def world_to_camera(d: np.ndarray) -> np.ndarray:
    """Inverse of :func:`camera_to_world` (the same map: it is its own inverse)."""
    return camera_to_world(d)


def _circle(height: int, width: int) -> tuple[float, float, float]:
    return (width - 1) / 2.0, (height - 1) / 2.0, min(width, height) / 2.0


def photo_pixel_to_direction(x: np.ndarray, y: np.ndarray, height: int, width: int) -> np.ndarray:
    """Direction (camera frame, unit) of photograph pixel ``(x, y)`` on the back hemisphere.

    Parameters
    ----------
    x, y : np.ndarray
        Pixel coordinates (column, row; pixel centres at integers), inside the circle.
    height, width : int
        The photograph's size in pixels.

    Returns
    -------
    np.ndarray
        ``(..., 3)`` unit directions ``[x_n, y_n, 1 - rho] / norm``, ``z >= 0``.
    """
    xc, yc, r = _circle(height, width)
    xn = (np.asarray(x, np.float64) - xc) / r
    yn = (np.asarray(y, np.float64) - yc) / r
    d = np.stack([xn, yn, 1.0 - np.hypot(xn, yn)], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def direction_to_photo_pixel(d: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Photograph pixel ``(x, y)`` that the paper's mapping gives a camera-frame direction.

    Directions of the front hemisphere (``z < 0``) are mirrored to the back one first. Solving
    ``d ~ [x_n, y_n, 1 - rho]`` for a unit ``d = (a, b, c)``, ``c >= 0``: with ``s = sqrt(a^2 +
    b^2)``, ``x_n = a / (s + c)`` and ``y_n = b / (s + c)``.

    Returns
    -------
    x, y : np.ndarray
        Pixel coordinates (column, row), within the circle.
    """
    d = np.asarray(d, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    a, b, c = d[..., 0], d[..., 1], np.abs(d[..., 2])
    s = np.hypot(a, b)
    xc, yc, r = _circle(height, width)
    return xc + r * a / (s + c), yc + r * b / (s + c)


def latlong_directions(height: int, width: int) -> np.ndarray:
    """World directions of the pixel centres of a lat-long map in abs's convention.

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` unit directions; row ``j`` at ``theta = pi j / (height - 1)``,
        column ``i`` at ``phi = 2 pi (i + 0.5) / width``, ``d = (sin theta sin phi, cos theta,
        -sin theta cos phi)``.
    """
    theta = np.pi * np.arange(height) / max(height - 1, 1)
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    return np.stack([st * np.sin(phi)[None, :], np.broadcast_to(ct, (height, width)),
                     -st * np.cos(phi)[None, :]], axis=-1)


def _remap(image: np.ndarray, x: np.ndarray, y: np.ndarray, border: int) -> np.ndarray:
    src = np.ascontiguousarray(image, np.float32)
    return cv2.remap(src, np.asarray(x, np.float32), np.asarray(y, np.float32),
                     interpolation=cv2.INTER_LINEAR, borderMode=border)


def environment_from_photograph(background: np.ndarray, width: int = 256) -> np.ndarray:
    """Lat-long HDR environment map made from a photograph (object already removed).

    Parameters
    ----------
    background : np.ndarray
        ``(height, width, 3)`` linear RGB, the photograph with the object's hole filled
        (:func:`abs.editing.holes.fill_background`).
    width : int
        Width of the map in pixels (its height is ``width // 2``).

    Returns
    -------
    np.ndarray
        ``(width // 2, width, 3)`` float32 lat-long map in abs's convention (module docstring),
        radiance in the photograph's unit, bilinearly sampled.
    """
    h, w = background.shape[:2]
    dirs = world_to_camera(latlong_directions(width // 2, width))
    x, y = direction_to_photo_pixel(dirs, h, w)
    return _remap(background, x, y, cv2.BORDER_REPLICATE)


def latlong_lookup(latlong: np.ndarray, d_world: np.ndarray) -> np.ndarray:
    """Bilinear radiance of a lat-long map (abs's convention) in world directions.

    Parameters
    ----------
    latlong : np.ndarray
        ``(H, W, 3)`` map.
    d_world : np.ndarray
        ``(..., 3)`` directions (normalised here).

    Returns
    -------
    np.ndarray
        ``(..., 3)`` float32 radiance, interpolated as Mitsuba's ``envmap`` (columns wrap).
    """
    d = np.asarray(d_world, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    hgt, wid = latlong.shape[:2]
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi), 1.0)
    t = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    x = u * wid - 0.5
    y = np.clip(t * (hgt - 1), 0.0, hgt - 1.0)
    shape = d.shape[:-1]
    # cv2.remap takes maps of fewer than 32767 columns: lay the queries out in rows of 1024.
    count = int(np.prod(shape))
    rows = max(1, -(-count // 1024))
    grid_x = np.zeros(rows * 1024, np.float32)
    grid_y = np.zeros(rows * 1024, np.float32)
    grid_x[:count], grid_y[:count] = x.ravel(), y.ravel()
    out = _remap(latlong, grid_x.reshape(rows, 1024), grid_y.reshape(rows, 1024), cv2.BORDER_WRAP)
    return out.reshape(rows * 1024, -1)[:count].reshape(shape + (latlong.shape[2],))


class EnvironmentSampler:
    """Importance sampling of a lat-long map by luminance times solid angle (as abs's renderer).

    A pixel is drawn with probability proportional to its luminance times ``sin theta`` of its
    cell (plus a floor of 1e-3 of the mean, so dark directions stay sampleable), then a uniform
    point in its ``(u, t)`` cell; the solid-angle density is ``p W H / (2 pi^2 sin theta)``.

    Parameters
    ----------
    latlong : np.ndarray
        ``(H, W, 3)`` linear RGB map.
    """

    def __init__(self, latlong: np.ndarray):
        self.latlong = np.asarray(latlong, np.float32)
        h, w = self.latlong.shape[:2]
        lum = self.latlong @ np.array([0.2126, 0.7152, 0.0722], np.float32)
        theta = (np.arange(h) + 0.5) / h * np.pi
        weight = np.maximum(lum, 0.0) * np.sin(theta)[:, None]
        weight = weight + 1e-3 * max(float(weight.mean()), 1e-12)
        self.pmf = (weight / weight.sum()).astype(np.float64)
        self._cdf = np.cumsum(self.pmf.ravel())

    def sample(self, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``count`` world directions (stratified in the CDF), their densities and radiance.

        Returns
        -------
        d : np.ndarray
            ``(count, 3)`` unit world directions.
        pdf : np.ndarray
            ``(count,)`` solid-angle densities, 1/sr.
        radiance : np.ndarray
            ``(count, 3)`` the map's bilinear radiance in those directions.
        """
        h, w = self.pmf.shape
        xi = (np.arange(count) + rng.random(count)) / count
        index = np.minimum(np.searchsorted(self._cdf, xi * self._cdf[-1]), h * w - 1)
        row, col = index // w, index % w
        u = (col + rng.random(count)) / w
        t = (row + rng.random(count)) / h
        theta, phi = t * np.pi, u * 2.0 * np.pi
        st = np.sin(theta)
        d = np.stack([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)], axis=-1)
        pdf = self.pmf[row, col] * w * h / (2.0 * np.pi ** 2 * np.maximum(st, 1e-9))
        return d, pdf, latlong_lookup(self.latlong, d)
