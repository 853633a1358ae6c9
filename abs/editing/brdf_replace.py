"""BRDF replacement: shade the object's normals with a measured BRDF under the photograph's
environment (Khan et al. 2006, sec. 6).

For each object pixel the paper sums the environment over about 400 importance-sampled directions,
weighted by the new BRDF:

    L_o(x) = 1/N sum_k f(w_k, w_o; n(x)) L_env(w_k) max(0, n(x) . w_k) / p(w_k),

with ``n(x)`` the normal from :mod:`abs.editing.gradients`, ``w_o`` the direction to the camera
and ``L_env`` the map of :func:`abs.editing.environment.environment_from_photograph`. There is no
visibility term: the object is convex to the method (it has no 3-D model to cast shadows with).

Our choices where the paper is silent:

- one set of ``N`` directions, drawn once (stratified, :class:`~abs.editing.environment.
  EnvironmentSampler`, abs's luminance-times-solid-angle density) and shared by all pixels: the
  image then shows no per-pixel Monte-Carlo noise, only a smooth bias that vanishes as ``N``
  grows; seeded, so an edit is reproducible;
- an orthographic view, ``w_o = (0, 0, -1)`` in the camera frame for every pixel;
- the BRDF is a MERL-layout table (``(3, 90, 90, 180)``, 1/sr; :func:`abs.brdf.measured.
  measured_table`: the shared neural fits or real MERL files) looked up at the nearest sample
  (:func:`abs.brdf.directions.merl_entries`).
"""

from __future__ import annotations

import numpy as np

from abs.brdf.directions import merl_entries
from abs.editing.environment import EnvironmentSampler, world_to_camera

__all__ = ["DEFAULT_SAMPLES", "tangent_frames", "shade_with_brdf"]

DEFAULT_SAMPLES = 400
"""Environment directions per pixel (the paper's "about 400")."""

_VIEW = np.array([0.0, 0.0, -1.0])  # towards the camera, camera frame


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents ``(t, b)`` completing each normal to a right-handed frame ``(t, b, n)``.

    Parameters
    ----------
    normals : np.ndarray
        ``(..., 3)`` unit normals.

    Returns
    -------
    t, b : np.ndarray
        ``(..., 3)`` unit vectors with ``t x b = n`` (Frisvad/Duff et al. branchless frame).
    """
    n = np.asarray(normals, np.float64)
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    bt = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return t, bt


def shade_with_brdf(normals: np.ndarray, mask: np.ndarray, latlong: np.ndarray, table: np.ndarray,
                    samples: int = DEFAULT_SAMPLES, seed: int = 0, chunk: int = 4096) -> np.ndarray:
    """Radiance of the object's pixels with a new BRDF under an environment map.

    Parameters
    ----------
    normals : np.ndarray
        ``(height, width, 3)`` unit normals, abs camera frame.
    mask : np.ndarray of bool
        ``(height, width)`` the object's pixels.
    latlong : np.ndarray
        ``(H, W, 3)`` lat-long environment (radiance), abs's convention, camera along world +z
        (:mod:`abs.editing.environment`).
    table : np.ndarray
        ``(3, 90, 90, 180)`` MERL-layout BRDF, 1/sr.
    samples : int
        Environment directions ``N`` (about 400 in the paper).
    seed : int
        Seed of the directions.
    chunk : int
        Pixels per batch (memory: ``chunk * samples * 3`` values).

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` float32 radiance on the object, 0 elsewhere.
    """
    m = np.asarray(mask, bool)
    flat_table = np.ascontiguousarray(table, np.float32).ravel()
    d_world, pdf, radiance = EnvironmentSampler(latlong).sample(samples, np.random.default_rng(seed))
    wi_cam = world_to_camera(d_world)                                    # (N, 3)
    weight = radiance.astype(np.float64) / pdf[:, None]                 # (N, 3)
    n = np.asarray(normals, np.float64)[m]                              # (P, 3)
    out = np.zeros((n.shape[0], 3))
    for start in range(0, n.shape[0], chunk):
        nn = n[start:start + chunk]
        t, b = tangent_frames(nn)
        frame = np.stack([t, b, nn], axis=1)                            # (p, 3, 3) rows t, b, n
        wi = np.einsum("pij,kj->pki", frame, wi_cam)                    # (p, N, 3) local
        wo = np.einsum("pij,j->pi", frame, _VIEW)                       # (p, 3)
        wo = np.broadcast_to(wo[:, None, :], wi.shape)
        visible = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        f = flat_table[merl_entries(wi, wo)]                            # (p, N, 3)
        cos_i = np.where(visible, wi[..., 2], 0.0)
        out[start:start + chunk] = np.einsum("pk,pkc,kc->pc", cos_i, f, weight) / samples
    image = np.zeros(m.shape + (3,), np.float32)
    image[m] = out
    return image
