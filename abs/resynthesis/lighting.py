"""The unseen part of the environment, fitted: a smooth map that lights the object as photographed.

One photograph shows the light from behind the object (the backdrop,
:mod:`~abs.resynthesis.backdrop`) but not the light from behind the camera, above or below, which
is most of what shades the object. The baseline guesses it by mirroring the photograph; here the
object itself serves as the light probe. A rendering is linear in the environment's radiance, so
with the material fixed the photograph is, per colour channel ``c``,

    photo_c = B0_c + sum_k g_kc B_kc,

``B0`` the rendering lit by the backdrop alone, ``B_k`` the rendering lit by the ``k``-th smooth
basis map alone (a bilinear "hat" on a coarse lat-long grid, zero on the backdrop; the hats sum
to one), ``g_kc`` its radiance.

**A hat's colour is the prior's** (the baseline's mirrored map, i.e. the photograph's own
colours): ``g_kc = a_k q_kc``, ``q_k`` the prior hat's colour normalised to mean 1, one unknown
``a_k`` per hat fitted over all three channels. A diffuse object cannot tell a redder light on a
bluer surface from the converse (only its highlights can, and a smooth map holds no sun), so
fitted per channel independently the hats it barely sees swung to saturated blue, green and
magenta, which a glass object then shows: on ``benchmarks/material_edit.py``'s sphere (three fit
seeds) the clear-glass edit's ΔE00 to the truth was 15.0-17.3, and is 13.9-15.2 with the shared
colour. The solve is bounded (``a >= 0``) with a weak pull of each level towards the prior's: a
direction the object does not reflect keeps the prior.

Tried and left out: a penalty on neighbouring hats' differences. It improved the clear-glass
score on the benchmark (ΔE00 about 13), but two-fold cross-validation over the object's pixels
rejects every weight tried (held-out RMSE 0.086 without, 0.111 at the smallest weight, rising
with it): the photograph gives no reason for it, so choosing it would be fitting the benchmark.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import lsq_linear

__all__ = ["hat_basis", "hat_averages", "solve_gains", "map_from_gains"]


def _hat(x: np.ndarray, nodes: np.ndarray, i: int, periodic: bool) -> np.ndarray:
    spacing = nodes[1] - nodes[0]
    d = np.abs(x - nodes[i])
    if periodic:
        d = np.minimum(d, 2 * np.pi - d)
    return np.clip(1.0 - d / spacing, 0.0, None)


def _factors(map_height: int, n_theta: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    theta = np.pi * np.arange(map_height) / max(map_height - 1, 1)
    phi = 2.0 * np.pi * (np.arange(2 * map_height) + 0.5) / (2 * map_height)
    t_nodes = np.linspace(0.0, np.pi, n_theta)
    p_nodes = 2.0 * np.pi * np.arange(n_phi + 1) / n_phi
    rows = np.array([_hat(theta, t_nodes, i, False) for i in range(n_theta)])
    cols = np.array([_hat(phi, p_nodes, j, True) for j in range(n_phi)])
    return rows, cols


def _expand(gains: np.ndarray, n_theta: int, n_phi: int) -> np.ndarray:
    """``(K, 3)`` gains to the ``(n_theta, n_phi, 3)`` grid (a pole's gain on its whole ring)."""
    grid = np.empty((n_theta, n_phi, gains.shape[1]))
    grid[0], grid[-1] = gains[0], gains[-1]
    grid[1:-1] = gains[1:-1].reshape(n_theta - 2, n_phi, -1)
    return grid


def hat_basis(map_height: int, n_theta: int = 7, n_phi: int = 8) -> np.ndarray:
    """Bilinear hat functions on a lat-long grid (abs's map convention), a partition of unity.

    Parameters
    ----------
    map_height : int
        Height of the map (width twice); keep it small, the result holds every function.
    n_theta : int
        Nodes in the polar angle from the zenith (0) to the nadir (pi), poles included.
    n_phi : int
        Nodes in azimuth (periodic) on every ring between the poles.

    Returns
    -------
    np.ndarray
        ``(2 + (n_theta - 2) n_phi, map_height, 2 map_height)`` float32; at each texel the
        functions sum to 1. The poles are one function each.
    """
    rows, cols = _factors(map_height, n_theta, n_phi)
    k = 2 + (n_theta - 2) * n_phi
    return np.asarray([map_from_gains(np.eye(k)[:, i:i + 1].repeat(3, 1), map_height, n_theta,
                                      n_phi)[..., 0] for i in range(k)], np.float32)


def hat_averages(latlong: np.ndarray, basis: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Each hat's solid-angle-weighted mean radiance of ``latlong`` over the texels ``where``.

    Returns
    -------
    np.ndarray
        ``(K, 3)``; a hat with no texel in ``where`` gets the mean over all of ``where``.
    """
    h = latlong.shape[0]
    weight = (np.sin(np.pi * np.arange(h) / max(h - 1, 1))[:, None] * where)[None] * basis
    total = weight.sum(axis=(1, 2))
    sums = np.einsum("khw,hwc->kc", weight, latlong)
    overall = latlong[where].mean(axis=0) if where.any() else np.zeros(3)
    return np.where(total[:, None] > 0, sums / np.maximum(total, 1e-12)[:, None], overall)


def solve_gains(photo: np.ndarray, fixed: np.ndarray, responses: np.ndarray, prior: np.ndarray,
                ridge: float) -> np.ndarray:
    """The hats' radiance that best explains the photograph (module docstring).

    Parameters
    ----------
    photo : np.ndarray
        ``(n, 3)`` the object's pixels, linear.
    fixed : np.ndarray
        ``(n, 3)`` the rendering of those pixels lit by the backdrop alone.
    responses : np.ndarray
        ``(K, n, 3)`` renderings lit by each hat of unit radiance.
    prior : np.ndarray
        ``(K, 3)`` prior radiance of each hat; its colour is kept, its level is the pull's target.
    ridge : float
        Weight of the pull towards the prior's level, relative to the mean squared response of a
        hat (dimensionless; small: the data decide wherever the object responds).

    Returns
    -------
    np.ndarray
        ``(K, 3)`` radiance >= 0, each row a multiple of the prior's row.
    """
    k = responses.shape[0]
    prior = np.asarray(prior, np.float64)
    level = prior.mean(axis=1)
    # A black prior hat has no colour to keep: grey.
    colour = np.where(level[:, None] > 0, prior / np.maximum(level, 1e-300)[:, None], 1.0)
    A = np.concatenate([(responses[:, :, c] * colour[:, c:c + 1]).T for c in range(3)])
    A = A.astype(np.float64)
    b = np.concatenate([photo[:, c] - fixed[:, c] for c in range(3)]).astype(np.float64)
    lam = np.sqrt(ridge * np.mean(np.sum(A * A, axis=0)))
    a = lsq_linear(np.vstack([A, lam * np.eye(k)]), np.concatenate([b, lam * level]),
                   bounds=(0.0, np.inf)).x
    return a[:, None] * colour


def map_from_gains(gains: np.ndarray, map_height: int, n_theta: int = 7,
                   n_phi: int = 8) -> np.ndarray:
    """``sum_k g_k hat_k`` at any resolution (the hats are separable in theta and phi).

    Parameters
    ----------
    gains : np.ndarray
        ``(K, C)`` radiance per hat, ordered as :func:`hat_basis`.
    map_height : int
        Height of the map (width twice).

    Returns
    -------
    np.ndarray
        ``(map_height, 2 map_height, C)`` float32.
    """
    rows, cols = _factors(map_height, n_theta, n_phi)
    grid = _expand(np.asarray(gains, np.float64), n_theta, n_phi)
    return np.einsum("it,jp,ijc->tpc", rows, cols, grid).astype(np.float32)
