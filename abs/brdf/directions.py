"""Direction pairs ↔ MERL table entries (Rusinkiewicz half/difference angles).

For unit directions ωi, ωo in the local shading frame (z = surface normal), the half vector is
h = (ωi + ωo)/|ωi + ωo| with polar angle θh and azimuth φh; the difference vector d is ωi rotated
by −φh about z and then by −θh about y, with angles θd, φd (FORMAT.md item 10 of the neural MERL
data; Rusinkiewicz 1998). Swapping ωi and ωo maps φd to φd + π, the same table entry
(reciprocity), so the order of the pair does not matter.
"""

from __future__ import annotations

import numpy as np

from abs.io.merl import MERL_SHAPE, merl_sample_angles

__all__ = ["rusinkiewicz_angles", "merl_entries", "merl_entry_measure", "uniform_hemisphere_directions"]

_CHANNEL_SIZE = MERL_SHAPE[1] * MERL_SHAPE[2] * MERL_SHAPE[3]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def uniform_hemisphere_directions(rng: np.random.Generator, count: int,
                                  max_theta: float = np.pi / 2) -> np.ndarray:
    """(count, 3) unit directions uniform in solid angle on the hemisphere z > 0, polar angle at
    most ``max_theta`` (radians)."""
    cos_theta = rng.uniform(np.cos(max_theta), 1.0, count)
    phi = rng.uniform(0.0, 2 * np.pi, count)
    sin_theta = np.sqrt(1 - cos_theta**2)
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta], axis=-1)


def rusinkiewicz_angles(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Half/difference angles of direction pairs.

    Parameters
    ----------
    wi, wo : np.ndarray
        (..., 3) directions in the local frame (z = normal); normalised here.

    Returns
    -------
    theta_h, theta_d, phi_d : np.ndarray
        Radians; θh, θd in [0, π], φd in (−π, π].
    """
    wi, wo = _unit(np.asarray(wi, np.float64)), _unit(np.asarray(wo, np.float64))
    h = _unit(wi + wo)
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    # Rotate ωi by −φh about z, then by −θh about y.
    cp, sp = np.cos(phi_h), np.sin(phi_h)
    x = cp * wi[..., 0] + sp * wi[..., 1]
    y = -sp * wi[..., 0] + cp * wi[..., 1]
    z = wi[..., 2]
    ct, st = np.cos(theta_h), np.sin(theta_h)
    dx, dz = ct * x - st * z, st * x + ct * z
    return theta_h, np.arccos(np.clip(dz, -1.0, 1.0)), np.arctan2(y, dx)


def merl_entries(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Flat MERL table indices of the sample nearest to each direction pair, per colour channel.

    The sample positions are those of :func:`abs.io.merl.merl_sample_angles`
    (θh = (i/90)²·π/2, θd = j/90·π/2, φd = k/180·π); each angle is rounded to the nearest one
    (θh through its square root), φd folded into [0, π) by reciprocity and k = 180 wrapped to 0.
    Pairs with a direction below the horizon are not rejected here: test ``wi[..., 2] > 0`` and
    ``wo[..., 2] > 0`` first.

    Parameters
    ----------
    wi, wo : np.ndarray
        (..., 3) directions in the local frame (z = normal).

    Returns
    -------
    np.ndarray
        int64 array of shape (..., 3): the entries of the R, G and B values of each pair in a
        flat (3·90·90·180,) table.
    """
    theta_h, theta_d, phi_d = rusinkiewicz_angles(wi, wo)
    n_h, n_d, n_phi = MERL_SHAPE[1:]
    i = np.clip(np.rint(n_h * np.sqrt(np.clip(theta_h, 0.0, None) / (np.pi / 2))), 0, n_h - 1)
    j = np.clip(np.rint(theta_d / (np.pi / 2) * n_d), 0, n_d - 1)
    k = np.rint(np.mod(phi_d, np.pi) / np.pi * n_phi) % n_phi
    flat = ((i.astype(np.int64) * n_d + j.astype(np.int64)) * n_phi + k.astype(np.int64))
    return flat[..., None] + _CHANNEL_SIZE * np.arange(3, dtype=np.int64)


def merl_entry_measure() -> np.ndarray:
    """The measure of direction-pair space each table entry stands for, sr².

    With dωi·dωo = 4 cosθd sinθd sinθh dθh dθd dφd dφh (the Jacobian of the half/difference
    parametrisation), an entry's cell has measure 4 cosθd sinθd sinθh Δθh Δθd Δφd · 2π (φh, by
    isotropy) · 2 (φd and φd + π share the entry); Δθh is the spacing of the non-uniform θh samples
    around the entry. Entries with a direction below the horizon get 0. Summed over a channel this
    is ≈ (2π)², the measure of all pairs of upper-hemisphere directions. Use it to average errors
    over directions instead of over table entries (a third of the entries lie at θh < 10°).

    Returns
    -------
    np.ndarray
        float64 (3·90·90·180,) in MERL order, the same for R, G and B.
    """
    theta_h, theta_d, phi_d = merl_sample_angles()
    n_h, n_d, n_phi = MERL_SHAPE[1:]
    d_theta_h = np.gradient((np.arange(n_h) / n_h) ** 2 * (np.pi / 2))[:, None, None]
    cell = 4 * np.cos(theta_d) * np.sin(theta_d) * np.sin(theta_h) * d_theta_h
    cell = cell * (np.pi / 2 / n_d) * (np.pi / n_phi) * 2 * np.pi * 2
    along = np.cos(theta_d) * np.cos(theta_h)
    across = np.sin(theta_d) * np.cos(phi_d) * np.sin(theta_h)
    cell[(along + across <= 0) | (along - across <= 0)] = 0.0
    return np.tile(cell.ravel(), 3)
