"""Unwrap photographs of a mirror ball into a lat-long environment map.

For each texel of the output map (direction ``l`` towards the environment, Mitsuba's ``envmap``
orientation, docs/conventions.md) find the ball point that reflects ``l`` into the camera, and
read the photograph there.

**Pinhole model** (the camera at a finite distance). With ``c`` the camera centre, ``o`` the ball
centre and ``R`` its radius, ``v = (c − o)/|c − o|``, the normal ``n = (v + l)/|v + l|``, the point
``p = o + R n``, which is projected with the calibrated camera. The mirror law holds at ``p`` for
the direction towards the camera from ``p``, ``v_p = (c − p)/|c − p|``, not from ``o``; so ``n`` is
refined by the fixed point ``n ← (v_p + l)/|v_p + l|`` (``iterations``; 0 is the formula above, and
each step shrinks the error by about ``R/|c − o|``). A direction is seen only if ``p`` faces the
camera, ``n · v > R/|c − o|``; others are set to zero.

**Orthographic model** (the baseline: the camera at infinity along ``v``). ``n = (v + l)/|v + l|``
and the pixel is the ball's projected centre plus ``r_px (n · x_cam, n · y_cam)``, with ``r_px``
the image radius of the ball's outline (``f tan asin(R/|c − o|)``); every ``n · v > 0`` counts as seen.

**Fresnel division.** A chrome ball reflects a fraction ``F(θ)`` of the light per channel,
``θ`` the angle between ``c − p`` and ``n``: the photograph is divided by chromium's Fresnel
reflectance (:func:`abs.probe.fresnel.conductor_reflectance`) with its per-channel complex IOR.

**Merging views.** Each view's texel gets the weight ``n · v_p`` (1 facing the camera, 0 at the
outline, where the ball is most foreshortened and a pixel covers the most directions); texels
outside the image or unseen weigh 0. The merged map is the weighted mean.

Texel directions follow Mitsuba's ``envmap`` (abs/render/environment.py): column ``i`` at
``u = (i + 0.5)/W``, row ``j`` at ``θ = π j/(H − 1)``, local direction
``(sin θ sin 2πu, cos θ, −sin θ cos 2πu)``, so the map drops into a scene with identity ``to_world``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from abs.camera.pinhole import project
from abs.errors import InputError
from abs.probe.fresnel import conductor_reflectance

__all__ = ["MODELS", "ProbeView", "latlong_directions", "unwrap_view", "merge_views"]

#: Camera models of :func:`unwrap_view`.
MODELS = ("pinhole", "orthographic")


@dataclass(frozen=True)
class ProbeView:
    """A calibrated photograph of the ball (linear RGB, OpenCV camera, docs/conventions.md).

    ``name`` names the view (its file) in errors.
    """

    name: str
    image: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray

    @property
    def center(self) -> np.ndarray:
        return -np.asarray(self.R).T @ np.asarray(self.t).reshape(3)


def latlong_directions(width: int, height: int) -> np.ndarray:
    """World unit directions of a lat-long map's texels, shape ``(height, width, 3)``."""
    u = (np.arange(width) + 0.5) / width
    theta = np.pi * np.arange(height) / max(height - 1, 1)
    phi = 2.0 * np.pi * u
    st = np.sin(theta)[:, None]
    return np.stack([st * np.sin(phi)[None, :], np.repeat(np.cos(theta)[:, None], width, 1),
                     -st * np.cos(phi)[None, :]], axis=-1)


def _normalize(x: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    return x / np.where(norm > 0, norm, 1.0)


def unwrap_view(view: ProbeView, ball_center: np.ndarray, ball_radius: float,
                directions: np.ndarray, *, model: str = "pinhole", iterations: int = 6,
                eta_rgb=None, k_rgb=None) -> tuple[np.ndarray, np.ndarray]:
    """Radiance of the environment in ``directions`` as one photograph of the ball shows it.

    Parameters
    ----------
    view : ProbeView
    ball_center : array-like, shape (3,)
        World position of the ball centre, metres.
    ball_radius : float
        Ball radius, metres.
    directions : ndarray, shape (..., 3)
        Unit world directions towards the environment (e.g. :func:`latlong_directions`).
    model : str
        ``"pinhole"`` or ``"orthographic"`` (module docstring).
    iterations : int
        Fixed-point refinements of the pinhole normal (0: the closed formula).
    eta_rgb, k_rgb : array-like, shape (3,), optional
        The ball's complex IOR per channel; when given the image is divided by its Fresnel
        reflectance.

    Returns
    -------
    radiance : ndarray, shape (..., 3)
        0 where the view does not see the direction.
    weight : ndarray, shape (...)
        How well the view sees each direction (``n · v_p``, 0 where unseen).

    Raises
    ------
    InputError
        Naming the view: the camera inside the ball, or the ball outside the photograph.
    """
    if model not in MODELS:
        raise InputError(None, "model", f"unknown {model!r}; one of {MODELS}")
    o = np.asarray(ball_center, np.float64).reshape(3)
    c = view.center
    dist = float(np.linalg.norm(c - o))
    if dist <= ball_radius:
        raise InputError(view.name, "ball", f"camera is {dist:.3g} m from the ball centre, inside "
                                            f"the ball (radius {ball_radius:.3g} m)")
    h, w = view.image.shape[:2]
    centre_px = project(view.K, view.R, view.t, o)
    if not np.all(np.isfinite(centre_px)) or not (0 <= centre_px[0] <= w - 1 and 0 <= centre_px[1] <= h - 1):
        raise InputError(view.name, "ball", f"the ball centre projects to {centre_px} pixels, "
                                            f"outside this {w}x{h} view: it does not see the ball")
    v = (c - o) / dist
    l = np.asarray(directions, np.float64)
    n = _normalize(v + l)
    if model == "pinhole":
        for _ in range(iterations):
            vp = _normalize(c - (o + ball_radius * n))
            n = _normalize(vp + l)
        p = o + ball_radius * n
        vp = _normalize(c - p)
        seen = (n @ v) > ball_radius / dist
        uv = project(view.K, view.R, view.t, p.reshape(-1, 3)).reshape(*l.shape[:-1], 2)
    else:
        vp = np.broadcast_to(v, n.shape)
        seen = (n @ v) > 0
        f = 0.5 * (view.K[0, 0] + view.K[1, 1])
        r_px = f * np.tan(np.arcsin(ball_radius / dist))
        axes = np.asarray(view.R)[:2]  # camera x (right) and y (down) in world coordinates
        uv = centre_px + r_px * (n @ axes.T)
    seen &= np.linalg.norm(v + l, axis=-1) > 1e-9  # straight behind the ball: no normal
    uv = np.where(np.isfinite(uv), uv, -1e6)
    inside = (uv[..., 0] >= 0) & (uv[..., 0] <= w - 1) & (uv[..., 1] >= 0) & (uv[..., 1] <= h - 1)
    weight = np.where(seen & inside, np.clip(np.sum(n * vp, axis=-1), 0.0, 1.0), 0.0)
    if not np.any(weight > 0):
        raise InputError(view.name, "ball", "no direction of the map is seen on the ball in this "
                                            "view (wrong ball centre or radius, or camera pose?)")
    flat = uv.reshape(-1, 1, 2).astype(np.float32)
    sampled = cv2.remap(np.ascontiguousarray(view.image, np.float32), flat[..., 0], flat[..., 1],
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    radiance = sampled.reshape(*l.shape[:-1], 3).astype(np.float64)
    if eta_rgb is not None:
        cos_i = np.clip(np.sum(n * vp, axis=-1), 0.0, 1.0)
        radiance = radiance / conductor_reflectance(cos_i, eta_rgb, k_rgb)
    radiance[weight <= 0] = 0.0
    return radiance, weight


def merge_views(unwrapped: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean of several views' :func:`unwrap_view` results (same directions).

    Returns
    -------
    radiance : ndarray, shape (..., 3)
        0 where no view sees the direction.
    weight : ndarray, shape (...)
        Sum of the views' weights (0: unrecovered).
    """
    total = sum(w for _, w in unwrapped)
    acc = sum(r * w[..., None] for r, w in unwrapped)
    return np.where(total[..., None] > 0, acc / np.where(total > 0, total, 1.0)[..., None], 0.0), total
