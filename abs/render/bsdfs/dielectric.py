"""``abs_dielectric``: smooth glass with a refractive index per colour channel and Beer-Lambert
absorption inside, both differentiable.

Why not Mitsuba's ``dielectric``: its ``eta`` is a single, non-differentiable float.

Dispersion. With a different IOR per channel, one light path cannot refract into three directions,
so the integrator renders in *channel passes* (see :mod:`abs.render.integrator`): in pass ``k``
this BSDF refracts with ``ior[k]`` and the integrator keeps channel ``k`` of the result. The
active channel arrives as per-lane data in ``si.time`` (abs scenes are static, so the time
coordinate is free): state on the Python object would be wrong, because Dr.Jit re-traces this
method during the backward pass, after the last pass has changed any such state. Choosing between reflection and refraction uses the active channel's Fresnel
reflectance, with the probability detached so the weight ``F / detach(F)`` carries the IOR
gradient.

Absorption. A closed glass mesh is entered and left through its surface, so every path segment
inside the glass ends at a hit of that surface *from inside* (``cos_theta(wi) < 0``). There the
BSDF multiplies its sample weight by ``exp(-absorption_per_m * si.t)``, ``si.t`` being the length
of the segment just travelled. This is exact Beer-Lambert attenuation for every inside segment
and keeps the plugin stateless.

Roughness (``roughness`` = Beckmann alpha, 0 = smooth). A rough interface is sampled as a random
microfacet normal ``m`` drawn with density ``D(m) cos(theta_m)`` (Gaussian slopes of standard
deviation ``alpha / sqrt(2)`` per axis, by Box-Muller from the second sample, which stays attached
to ``alpha``), then reflected or refracted about ``m``, chosen by the Fresnel reflectance at
``wi.m`` as in the smooth case, and weighted ``|wi.m| G(wi, wo, m) / (|wi.n| |m.n|)`` (Walter
et al. 2007, eq. 41; Smith G with the Beckmann rational approximation). The BSDF keeps no ``eval``: rough glass is rendered by BSDF
sampling alone (no next-event estimation through it, so MIS treats its samples as delta samples),
which is unbiased and keeps the smooth case untouched. At ``alpha = 0`` the smooth formulas are
selected, so the smooth glass is reproduced bit for bit; there the derivative with respect to
``alpha`` is zero (the spread is symmetric, so the image changes at second order only).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["DielectricBSDF", "PLUGIN"]

PLUGIN = "abs_dielectric"


def _vec3(props, key: str, default: float) -> list[float]:
    if key not in props:
        return [default] * 3
    value = props.get(key)
    try:
        return [float(value[i]) for i in range(3)]
    except TypeError:
        return [float(value)] * 3


def _smith_g1(v: mi.Vector3f, m: mi.Vector3f, alpha: mi.Float) -> mi.Float:
    """Smith masking of direction ``v`` for Beckmann roughness ``alpha`` (Walter et al. 2007's
    rational approximation, exactly 1 when ``alpha tan(theta) < 1/1.6``)."""
    cos_v = mi.Frame3f.cos_theta(v)
    tan_v = dr.safe_sqrt(1.0 - dr.square(cos_v)) / dr.maximum(dr.abs(cos_v), 1e-12)
    a = 1.0 / dr.maximum(alpha * tan_v, 1e-12)
    g = (3.535 * a + 2.181 * dr.square(a)) / (1.0 + 2.276 * a + 2.577 * dr.square(a))
    g = dr.select(a >= 1.6, 1.0, g)
    return dr.select(dr.dot(v, m) * cos_v > 0.0, g, 0.0)


class DielectricBSDF(mi.BSDF):
    """Dielectric interface with per-channel IOR ``ior`` (interior over exterior, exterior is
    vacuum/air with IOR 1), interior absorption ``absorption`` in 1/m and Beckmann ``roughness``
    (alpha; 0: smooth)."""

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        self.ior = mi.Color3f(_vec3(props, "ior", 1.5))
        self.absorption = mi.Color3f(_vec3(props, "absorption", 0.0))
        self.roughness = dr.opaque(mi.Float, float(props.get("roughness", 0.0)))
        reflection = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
        transmission = (mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.FrontSide
                        | mi.BSDFFlags.BackSide | mi.BSDFFlags.NonSymmetric)
        self.m_components = [reflection, transmission]
        self.m_flags = reflection | transmission

    @staticmethod
    def _channel_value(rgb: mi.Color3f, si) -> mi.Float:
        channel = mi.UInt32(dr.clip(si.time, 0.0, 2.0))
        return dr.select(channel == 0, rgb.x, dr.select(channel == 1, rgb.y, rgb.z))

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        cos_theta_i = mi.Frame3f.cos_theta(wi)
        rough = self.roughness > 0.0
        m = self._microfacet_normal(sample2)
        # The interface seen by this sample: the microfacet when rough; the smooth one's cosine
        # is selected (not recomputed) at alpha = 0 so that the smooth case stays bit for bit.
        cos_i = dr.select(rough, dr.dot(wi, m), cos_theta_i)
        eta = self._channel_value(self.ior, si)
        # Fresnel reflectance of every channel at this angle; mi.fresnel handles the inside case.
        f_r = mi.Color3f(mi.fresnel(cos_i, self.ior.x)[0], mi.fresnel(cos_i, self.ior.y)[0],
                         mi.fresnel(cos_i, self.ior.z)[0])
        f_k, cos_theta_t, eta_it, eta_ti = mi.fresnel(cos_i, eta)

        has_r = ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
        has_t = ctx.is_enabled(mi.BSDFFlags.DeltaTransmission, 1)
        p_r = dr.detach(f_k)
        p_r = dr.select(has_r & has_t, p_r, dr.select(has_r, 1.0, 0.0))
        select_r = sample1 <= p_r

        bs = dr.zeros(mi.BSDFSample3f)
        bs.pdf = dr.select(select_r, p_r, 1.0 - p_r)
        bs.sampled_component = dr.select(select_r, mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = dr.select(select_r, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                    mi.UInt32(+mi.BSDFFlags.DeltaTransmission))
        smooth_wo = dr.select(select_r, mi.reflect(wi), mi.refract(wi, cos_theta_t, eta_ti))
        normal = mi.Normal3f(m)
        rough_wo = dr.select(select_r, mi.reflect(wi, normal), mi.refract(wi, normal, cos_theta_t, eta_ti))
        bs.wo = dr.select(rough, rough_wo, smooth_wo)
        bs.eta = dr.select(select_r, 1.0, eta_it)

        weight_r = f_r / dr.maximum(p_r, 1e-12)
        weight_t = (1.0 - f_r) / dr.maximum(1.0 - p_r, 1e-12)
        if ctx.mode == mi.TransportMode.Radiance:
            # Radiance is compressed by eta^2 on refraction (non-symmetric BSDF, Veach 1997 ch. 5).
            weight_t = weight_t * dr.square(eta_ti)
        weight = dr.select(select_r, weight_r, weight_t)
        weight = dr.select(rough, weight * self._microfacet_weight(wi, bs.wo, m, select_r), weight)

        # Beer-Lambert over the segment that ended here, if it ran inside the glass.
        inside = cos_theta_i < 0.0
        weight = dr.select(inside, weight * dr.exp(-self.absorption * si.t), weight)
        return bs, weight & (active & (bs.pdf > 0.0))

    def _microfacet_normal(self, sample2: mi.Point2f) -> mi.Vector3f:
        """Beckmann normal with density ``D(m) cos(theta_m)``: Gaussian slopes by Box-Muller,
        attached to ``alpha`` (reparameterised sampling)."""
        radius = self.roughness * dr.sqrt(-dr.log(dr.maximum(1.0 - sample2.x, 1e-12)))
        sin_phi, cos_phi = dr.sincos(dr.two_pi * sample2.y)
        return dr.normalize(mi.Vector3f(-radius * cos_phi, -radius * sin_phi, 1.0))

    def _microfacet_weight(self, wi, wo, m, select_r) -> mi.Float:
        """``|wi.m| G(wi, wo, m) / (|wi.n| |m.n|)``, zero for an impossible configuration."""
        alpha = self.roughness
        cos_i, cos_o, cos_i_m = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo), dr.dot(wi, m)
        g = _smith_g1(wi, m, alpha) * _smith_g1(wo, m, alpha)
        weight = dr.abs(cos_i_m) * g / dr.maximum(dr.abs(cos_i) * m.z, 1e-12)
        # Reflection stays on the side it came from and refraction crosses; m must face wi.
        valid = (cos_i_m * cos_i > 0.0) & dr.select(select_r, cos_o * cos_i > 0.0, cos_o * cos_i < 0.0)
        return dr.select(valid, weight, 0.0)

    def eval(self, ctx, si, wo, active=True):
        return mi.Color3f(0.0)

    def pdf(self, ctx, si, wo, active=True):
        return mi.Float(0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return mi.Color3f(0.0), mi.Float(0.0)

    def traverse(self, callback):
        callback.put("ior", self.ior, mi.ParamFlags.Differentiable)
        callback.put("absorption", self.absorption, mi.ParamFlags.Differentiable)
        callback.put("roughness", self.roughness, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return f"DielectricBSDF[ior={self.ior}, absorption={self.absorption}, roughness={self.roughness}]"


mi.register_bsdf(PLUGIN, lambda props: DielectricBSDF(props))
