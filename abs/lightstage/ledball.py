"""LED positions from a mirror ball's highlights (issue 27, part 3).

A chrome ball of known radius sits off-centre on the turntable. In a frame lit by one LED, the
ball shows that LED as a small highlight; the camera ray through the highlight's centroid meets
the ball at a point ``p`` whose normal ``n`` reflects the ray into the direction ``r`` of the LED
(law of reflection), so the LED lies on the line ``p + s r``, ``s > 0``. As the table turns, the
ball moves around the axis and the lines from its successive positions cross at the LED: the LED's
position is their least-squares intersection, pulled weakly towards the geometry file's position
(a prior, ``sigma_prior_m``) so that an LED seen from too narrow a baseline stays well posed.

Accuracy is set by the highlight's centroid: a pixel error ``du`` moves the normal by about
``du / (f R)`` times the camera distance (``f`` the focal length in pixels, ``R`` the ball radius)
and the reflected ray by twice that. The ball's centre at angle 0 (object frame) and its radius are
inputs of the calibration folder (measured, or from :func:`abs.probe.ball.triangulate_ball`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.camera.pinhole import project, ray_directions
from abs.lightstage.geometry import Camera

__all__ = ["highlight_centroid", "reflected_ray", "LedFix", "triangulate_led"]


def highlight_centroid(image: np.ndarray, camera: Camera, ball_center: np.ndarray, radius_m: float,
                       min_peak: float = 0.05, window_px: int = 3, refine: bool = True) -> np.ndarray | None:
    """Sub-pixel ``(u, v)`` of the brightest highlight on the ball's disc, or None.

    Parameters
    ----------
    image : np.ndarray
        (H, W, 3) linear frame of the ball lit by one LED, pixel values.
    camera : Camera
        The camera that took it.
    ball_center : np.ndarray
        (3,) ball centre at this frame's turntable angle, world frame, metres.
    radius_m : float
        Ball radius, metres.
    min_peak : float
        Highlights whose peak (channel mean, above the median of the ball's box) is below this are not
        found (the LED is not reflected into the camera, or is too dim).
    window_px : int
        Half-size of the window around the peak whose pixels make the centroid.
    refine : bool
        Refine the centroid by fitting a round Gaussian spot and a constant to the window.

    Returns
    -------
    np.ndarray or None
        (2,) pixel coordinates (pixel-centre convention), or None when no highlight.
    """
    lum = np.nan_to_num(np.asarray(image, np.float64).mean(axis=2), nan=1.0)
    # Search only the ball's projected disc (its bounding box, padded): other bright pixels
    # (a stray reflection of the rig) are not the ball's highlight.
    uv_c = project(camera.K, camera.R, camera.t, ball_center[None, :])[0]
    depth = float((camera.R @ ball_center + camera.t)[2])
    r_px = camera.K[0, 0] * radius_m / depth + 2.0
    h, w = lum.shape
    u0, u1 = int(max(0, np.floor(uv_c[0] - r_px))), int(min(w, np.ceil(uv_c[0] + r_px) + 1))
    v0, v1 = int(max(0, np.floor(uv_c[1] - r_px))), int(min(h, np.ceil(uv_c[1] + r_px) + 1))
    if u0 >= u1 or v0 >= v1:
        return None
    # The background (the ball's dark mirror image of the rig, sensor offset) from the disc's box.
    lum = lum - np.median(lum[v0:v1, u0:u1])
    box = lum[v0:v1, u0:u1]
    j, i = np.unravel_index(np.argmax(box), box.shape)
    peak = box[j, i]
    if not peak >= min_peak:
        return None
    v_peak, u_peak = v0 + j, u0 + i
    ys = slice(max(0, v_peak - window_px), min(h, v_peak + window_px + 1))
    xs = slice(max(0, u_peak - window_px), min(w, u_peak + window_px + 1))
    win = lum[ys, xs]
    # Pixels below a fifth of the peak are mostly noise: they would drag the centroid towards
    # the window's centre.
    weight = np.where(win > 0.2 * peak, win, 0.0)
    vv, uu = np.mgrid[ys, xs]
    start = np.array([np.sum(weight * uu), np.sum(weight * vv)]) / np.sum(weight)
    if not refine or win.size < 9:
        return start
    # The thresholded centroid is pulled towards the peak pixel's centre (pixel locking, ~0.05 px
    # here, millimetres at the LED along the lines' weak direction): a round Gaussian spot plus a
    # background fitted to the window removes that bias.
    from scipy.optimize import least_squares

    def residual(x):
        a, u, v, s, b = x
        return (a * np.exp(-((uu - u) ** 2 + (vv - v) ** 2) / (2.0 * s * s)) + b - win).ravel()

    x0 = np.array([peak, start[0], start[1], 1.0, 0.0])
    lo = [0.0, xs.start - 0.5, ys.start - 0.5, 0.3, -np.inf]
    hi = [np.inf, xs.stop - 0.5, ys.stop - 0.5, float(window_px), np.inf]
    fit = least_squares(residual, x0, bounds=(lo, hi), x_scale=[peak, 0.1, 0.1, 0.1, 0.01 * peak])
    return fit.x[1:3] if fit.status > 0 else start


def reflected_ray(camera: Camera, ball_center: np.ndarray, radius_m: float,
                  uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The line towards the LED from a highlight at pixel ``uv``.

    Returns ``(point on the ball (3,), unit direction (3,), cos_nv)``, world frame, metres;
    ``cos_nv`` is the cosine between the ball's normal there and the direction to the camera: a
    pixel's error turns the normal by about ``1 / cos_nv`` times more near the limb. None when the
    camera ray through ``uv`` misses the ball (a centroid pulled off the limb).
    """
    o, d = ray_directions(camera.K, camera.R, camera.t, np.asarray(uv, np.float64)[None, :])
    o, d = o[0], d[0]
    oc = o - ball_center
    b = float(d @ oc)
    disc = b * b - (float(oc @ oc) - radius_m * radius_m)
    if disc < 0.0:
        return None
    p = o + (-b - np.sqrt(disc)) * d
    n = (p - ball_center) / radius_m
    cos_nv = -float(d @ n)
    return p, d + 2.0 * cos_nv * n, cos_nv


@dataclass(frozen=True)
class LedFix:
    """One LED's position from its highlights.

    Attributes
    ----------
    position : np.ndarray
        (3,) estimated position, world frame, metres.
    lines : int
        Number of highlight lines used.
    rms_line_distance_m : float
        RMS distance of the estimate from its lines, metres (NaN without lines).
    sigma_direction_rad : float
        The lines' direction uncertainty used (given, or estimated from their scatter).
    """

    position: np.ndarray
    lines: int
    rms_line_distance_m: float
    sigma_direction_rad: float


def _solve(points, directions, prior, sigma_prior_m, sigma_direction_rad, scale):
    A = np.eye(3) / sigma_prior_m ** 2
    rhs = prior / sigma_prior_m ** 2
    for p, r, s in zip(points, directions, scale):
        P = np.eye(3) - np.outer(r, r)
        w = (s / (sigma_direction_rad * np.linalg.norm(prior - p))) ** 2
        A += w * P
        rhs += w * P @ p
    return np.linalg.solve(A, rhs)


def triangulate_led(points: np.ndarray, directions: np.ndarray, prior: np.ndarray,
                    sigma_prior_m: float = 0.02, sigma_direction_rad: float | None = None,
                    cos_nv: np.ndarray | None = None) -> LedFix:
    """The point closest to lines ``points[i] + s directions[i]``, with a Gaussian prior.

    Minimises ``sum_i |P_i (x - p_i)|^2 / (s_i |prior - p_i|)^2 + |x - prior|^2 / sigma_prior^2``
    with ``P_i = I - r_i r_i^T`` and ``s_i = sigma_direction / cos_nv_i``: squared distances from
    the lines, each weighted by the lateral uncertainty its direction error gives at the LED's
    distance (highlights near the ball's limb are less certain), plus the geometry file's position
    as a prior. Linear in ``x``.

    The lines of a ball circling a few centimetres from the axis, half a metre from the LED, cross
    at a few degrees: across them the position is pinned to the lines' lateral error, along them
    (towards the LED) about ten times less well, and there the balance with the prior depends on
    ``sigma_direction``. Left as None, it is estimated from the lines' own scatter (a first solve
    with 0.005 rad, then ``sqrt(sum (d_i cos_nv_i / D_i)^2 / (2N - 3))`` from the distances
    ``d_i`` of the estimate from the lines, floored at 1e-4 rad) when there are at least 3 lines.

    Parameters
    ----------
    points, directions : np.ndarray
        (N, 3) points on the lines (metres) and their directions (unit), world frame; N may be 0.
    prior : np.ndarray
        (3,) position from the geometry file, metres.
    sigma_prior_m : float
        Standard deviation of the geometry file's positions, metres.
    sigma_direction_rad : float or None
        Standard deviation of a highlight line's direction where the ball faces the camera,
        radians; None: estimated (see above).
    cos_nv : np.ndarray, optional
        (N,) :func:`reflected_ray`'s ``cos_nv`` per line (clipped at 0.1); 1 when omitted.
    """
    prior = np.asarray(prior, np.float64)
    points, directions = np.asarray(points, np.float64).reshape(-1, 3), np.asarray(directions, np.float64).reshape(-1, 3)
    scale = np.ones(len(points)) if cos_nv is None else np.maximum(np.asarray(cos_nv, np.float64), 0.1)
    sigma = 0.005 if sigma_direction_rad is None else sigma_direction_rad
    x = _solve(points, directions, prior, sigma_prior_m, sigma, scale)
    if len(points) == 0:
        return LedFix(x, 0, float("nan"), sigma)

    def distances(x):
        off = x[None, :] - points
        perp = off - np.sum(off * directions, 1)[:, None] * directions
        return np.sqrt(np.sum(perp * perp, 1))

    if sigma_direction_rad is None and len(points) >= 3:
        angular = distances(x) * scale / np.linalg.norm(prior[None, :] - points, axis=1)
        sigma = max(float(np.sqrt(np.sum(angular ** 2) / (2 * len(points) - 3))), 1e-4)
        x = _solve(points, directions, prior, sigma_prior_m, sigma, scale)
    return LedFix(x, len(points), float(np.sqrt(np.mean(distances(x) ** 2))), sigma)
