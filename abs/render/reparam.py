"""Visibility-aware gradients by reparameterising ray directions (harmonic-weight warp fields).

When a parameter moves a surface (``<object>.pose``), silhouettes move across the image and the
pixel integral's derivative gains a boundary term that plain automatic differentiation misses.
Following Loubet et al. 2019 ("Reparameterizing discontinuous integrands for differentiable
rendering") with the harmonic weights of Bangaru et al. 2020 (as in Mitsuba 2/3.0's
``reparameterize_ray``, which Mitsuba 3.9 no longer ships), each sampled direction ``d`` is
replaced by ``d + V(d) * dtheta``, where ``V`` is a smooth interpolation of how the surface points
seen around ``d`` move. Discontinuities then stay fixed in the integration variable, and the
Jacobian determinant ``1 + div V`` accounts for the change of variables.

Both ``V`` and ``div V`` enter only through derivatives: the returned direction equals ``d`` and
the determinant equals 1 in value, so primal images are unchanged.

The boundary test (how close an auxiliary hit lies to a silhouette) is ``|cos|`` between the
auxiliary ray and the hit's geometric normal, which vanishes at silhouettes of closed smooth
meshes (the objects whose pose we fit). Static discontinuities need no warp.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["reparameterize"]


def reparameterize(scene: mi.Scene, origin: mi.Point3f, d: mi.Vector3f, sampler: mi.Sampler,
                   kappa: float = 2e4, exponent: float = 3.0, n_aux: int = 4,
                   active=True) -> tuple[mi.Vector3f, mi.Float]:
    """Reparameterise rays ``(origin, d)``; returns ``(d_warped, det)``.

    Parameters
    ----------
    kappa : float
        Concentration of the von Mises-Fisher distribution of auxiliary rays; the warp field is
        smoothed over an angular radius of about ``1 / sqrt(kappa)`` radians (choose it close to a
        pixel's angular size).
    exponent : float
        Exponent of the harmonic weights.
    n_aux : int
        Auxiliary rays per direction (antithetic pairs).
    """
    d = dr.detach(d)
    origin = dr.detach(origin)
    frame = mi.Frame3f(d)
    z_sum = mi.Float(0.0)
    dz_sum = mi.Vector3f(0.0)
    v_sum = mi.Vector3f(0.0)
    div_sum = mi.Float(0.0)
    sample = None
    for i in range(n_aux):
        # Antithetic pairs halve the variance of the (odd) warp-field estimate.
        if i % 2 == 0:
            sample = sampler.next_2d(active)
            omega_local = mi.warp.square_to_von_mises_fisher(sample, kappa)
        else:
            omega_local = mi.Vector3f(-omega_local.x, -omega_local.y, omega_local.z)
        omega = frame.to_world(omega_local)
        ray = mi.Ray3f(origin, omega)
        si = scene.ray_intersect(ray, mi.RayFlags.All | mi.RayFlags.FollowShape, False, active)
        hit = si.is_valid()
        # Attached direction to the (moving) hit point; no motion where nothing is hit.
        v_dir = dr.select(hit, dr.normalize(si.p - origin), omega)
        v_dot = v_dir - dr.detach(v_dir)
        boundary = dr.select(hit, dr.abs(dr.dot(dr.detach(si.n), omega)), 1.0)
        inv_vmf = dr.exp(dr.fma(-omega_local.z, kappa, kappa))
        w_denom = inv_vmf - 1.0 + boundary
        w_denom_rcp = dr.select(w_denom > 1e-4, dr.rcp(w_denom), 0.0)
        w = dr.detach(dr.power(w_denom_rcp, exponent) * inv_vmf)
        # Gradient of the weight with respect to the central direction d.
        dw = dr.clip(inv_vmf * w * w_denom_rcp * kappa * exponent, -1e10, 1e10) * \
            frame.to_world(mi.Vector3f(omega_local.x, omega_local.y, 0.0))
        dw = dr.detach(dw)
        z_sum += w
        dz_sum += dw
        v_sum += w * v_dot
        div_sum += dr.dot(dw, v_dot)
    inv_z = dr.select(z_sum > 0.0, dr.rcp(z_sum), 0.0)
    warp = v_sum * inv_z
    divergence = div_sum * inv_z - dr.dot(v_sum, dz_sum) * dr.square(inv_z)
    return d + warp, 1.0 + divergence
