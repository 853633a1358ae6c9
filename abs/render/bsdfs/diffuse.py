"""``abs_diffuse``: the ``diffuse`` material's BSDF, a Lambertian surface with an optional
anisotropic lobe of woven threads (``anisotropy``), differentiable in the lobe's weights.

Why not Mitsuba's ``diffuse``: it has no anisotropic lobe. A ``diffuse`` material whose file names
a thread field (``anisotropy``, ``thread_direction``, ``thread_roughness``; the diagnosis adds
``anisotropy = [0, 0]`` when it tries the effect) compiles to this plugin, at the null value too,
so that the parameter exists wherever a fit may release it; without thread fields a material is
Mitsuba's ``diffuse`` itself (:mod:`abs.scene.materials.diffuse`). At the null value it is Mitsuba's
``diffuse`` operation for operation (the same warp, pdf and texture lookup): detached at
``[0, 0]`` it does not trace the lobes at all (they cost about 40 % of a render), attached (a
derivative at the null value) the lobes enter as ``x * 1 + 0``; both render the same image bit
for bit (``tests/test_cloth_anisotropy.py``).

Model (units: BRDF in 1/sr). A plain weave is warp threads along ``t`` and weft threads across
them. A thread is a cylinder: the normals of its surface turn by up to 90 degrees across the
thread but hardly along it (only by the crimp of the weave, where it passes over and under the
crossing threads). As microfacets, that is an anisotropic slope distribution: narrow along the
thread (GGX ``alpha_along``), wide across it (``alpha_across``). The BRDF is::

    f    = rho * ((1 - a_warp - a_weft) / pi + a_warp f_l(warp) + a_weft f_l(weft))
    f_l  = f_s + f_ms
    f_s  = D(h) G(wi, wo) / (4 cos_i cos_o)
    f_ms = (1 - E(wi)) (1 - E(wo)) / (pi (1 - E_avg))

``rho`` the reflectance (a colour or a texture), ``a = anisotropy = [a_warp, a_weft]`` the
fractions of the reflected light that leave by the threads' lobes (each in [0, 0.5], so the
Lambertian weight stays >= 0), ``D`` the anisotropic GGX distribution in the frame of the threads
(warp: alpha ``(along, across)`` about ``t``; weft: the same turned by 90 degrees), ``G`` Smith's
shadowing-masking and the Fresnel factor 1 (a fibre's sheen is folded into ``a``; Mitsuba's
``roughconductor`` with ``material = "none"`` is this ``f_s``, tested). ``f_ms`` is Kulla and
Conty's (2017) multiple-scattering term: ``E(w)`` the single-scattering lobe's directional albedo
(tabulated on loading over 33 polar angles and 9 azimuths, bilinear), ``E_avg`` its cosine-weighted
mean. Why this form:

- **Lambertian at 0**: ``a = 0`` is the plain model exactly.
- **Energy**: single scattering alone loses the light the threads mask (half of it for alphas
  0.3 and 1: the lobe would darken the cloth, and ``a`` would stand in for a wrong reflectance);
  with ``f_ms`` every direction's albedo is ``E + (1 - E) = 1`` times ``rho`` (to 1.5 %, the
  table's interpolation; tested), the Lambertian's. The lobes redistribute light over
  directions, they neither add nor remove any, so ``a`` is nearly orthogonal to a fitted
  reflectance or brightness.
- **Reciprocity**: ``f_s`` and ``f_ms`` are symmetric in ``wi`` and ``wo`` (tested).
- **Colour**: the lobes carry ``rho``: the light leaving a dyed thread has crossed its fibres.

Thread direction: ``thread_direction`` is a fixed direction in world space, projected onto each
shading point's tangent plane (``t``); where it is normal to the surface (less than 1e-4 of it in
the plane) the shading frame's first tangent is used. Fixed, not fitted: cloth lies flat and its
weave is usually along an edge of the table; ``a_warp`` against ``a_weft`` tells which of the two
directions in the plane carries the stronger lobe.

Sampling: cosine-weighted hemisphere, as Mitsuba's ``diffuse`` does, whatever ``a``: the lobes are
broad (alpha >= 0.05 along, typically 0.3 along and 1 across), and a pdf independent of ``a``
keeps the null bit for bit, next-event estimation's MIS weights unchanged, and the derivative
with respect to ``a`` (it only reweights samples) unbiased in every render mode. The sample
weight is ``rho (1 - a_warp - a_weft + pi (a_warp f_l(warp) + a_weft f_l(weft)))``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.jit import in_use, opaque

__all__ = ["DiffuseBSDF", "PLUGIN"]

PLUGIN = "abs_diffuse"

# Below this length of the thread direction projected onto the tangent plane, the direction is
# normal to the surface and the shading frame's own tangent stands in (no 0/0).
_IN_PLANE_EPS = 1e-4


# The albedo table: directions of incidence at _N_THETA polar angles from 0 to 90 degrees and
# _N_PHI azimuths from the warp (0) to the weft (90 degrees; the anisotropic GGX is symmetric
# under x -> -x and y -> -y), each integrated over _N_SAMPLES^2 stratified cosine-weighted
# outgoing directions.
_N_THETA, _N_PHI, _N_SAMPLES = 33, 9, 96


def albedo_table(bsdf: "DiffuseBSDF") -> tuple[mi.Float, float]:
    """The warp lobe's directional albedo ``E(theta, phi) = int f_s cos_o d omega_o`` on the
    (_N_THETA x _N_PHI) grid, row-major, and its cosine-weighted average over incident directions
    ``E_avg = int E cos_i / pi d omega_i`` (of the bilinear interpolation that
    :meth:`DiffuseBSDF.albedo` evaluates, by the same stratified directions)."""
    entries = _N_THETA * _N_PHI
    per = _N_SAMPLES * _N_SAMPLES
    lane = dr.arange(mi.UInt32, entries * per)
    entry, k = lane // per, lane % per
    theta = mi.Float(entry // _N_PHI) * (0.5 * dr.pi / (_N_THETA - 1))
    # The last polar angle is grazing: evaluate just above it (E is continuous there).
    theta = dr.minimum(theta, 0.5 * dr.pi - 1e-3)
    phi = mi.Float(entry % _N_PHI) * (0.5 * dr.pi / (_N_PHI - 1))
    sin_t, cos_t = dr.sincos(theta)
    sin_p, cos_p = dr.sincos(phi)
    wi = mi.Vector3f(sin_t * cos_p, sin_t * sin_p, cos_t)
    wo = mi.warp.square_to_cosine_hemisphere(_stratified(k))
    # Cosine-weighted directions: E is the mean of pi f_s.
    table = dr.block_sum(dr.pi * bsdf.single_scattering(wi, wo), per) / per
    dr.make_opaque(table)
    bsdf.table = table  # albedo() reads it
    average = dr.mean(bsdf.albedo(mi.warp.square_to_cosine_hemisphere(_stratified(dr.arange(mi.UInt32, per)))))
    return table, float(average[0])


def _stratified(k: mi.UInt32) -> mi.Point2f:
    """Centres of the cells of a _N_SAMPLES x _N_SAMPLES grid on the unit square (cell ``k``)."""
    return mi.Point2f((mi.Float(k % _N_SAMPLES) + 0.5) / _N_SAMPLES,
                      (mi.Float(k // _N_SAMPLES) + 0.5) / _N_SAMPLES)


class DiffuseBSDF(mi.BSDF):
    """Lambertian reflectance with the threads' lobes (see the module docstring).

    Mitsuba properties: ``reflectance`` (a texture; default 0.5), ``anisotropy_warp`` and
    ``anisotropy_weft`` (the lobes' weights, default 0; the parameter ``anisotropy`` holds both),
    ``thread_direction`` (a world-frame vector, default +x), ``thread_along`` and
    ``thread_across`` (GGX alphas of a thread, default 0.3 and 1).
    """

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        self.reflectance = props.get_texture("reflectance", 0.5)
        # Properties hold no 2-vectors: the pairs arrive as separate numbers.
        self.anisotropy = opaque(mi.Float, np.array([float(props.get("anisotropy_warp", 0.0)),
                                                     float(props.get("anisotropy_weft", 0.0))]))
        thread = props.get("thread_direction", mi.ScalarVector3f(1.0, 0.0, 0.0))
        self.thread = mi.Vector3f(*[opaque(mi.Float, np.array([float(thread[i])]))
                                    for i in range(3)])
        self.along = opaque(mi.Float, np.array([float(props.get("thread_along", 0.3))]))
        self.across = opaque(mi.Float, np.array([float(props.get("thread_across", 1.0))]))
        self.table, average = albedo_table(self)
        # f_ms = (1 - E(wi)) (1 - E(wo)) / (pi (1 - E_avg)); E_avg < 1 for alpha >= 0.05.
        self.ms_scale = opaque(mi.Float, np.array([1.0 / (dr.pi * max(1.0 - average, 1e-6))]))
        flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [flags]
        self.m_flags = flags
        self._check_lobes()

    def _check_lobes(self) -> None:
        """Whether the lobes are traced at all: not at the null value unless the weights are
        attached to the AD graph (a derivative at the null value needs them). Tracing them costs
        about 40 % of a render of a diffuse scene; either way the plain surface is bit for bit
        the same. Decided when the weights are written (``parameters_changed``), before any
        render traces the BSDF, and only a new write changes it."""
        self.lobes = in_use(self.anisotropy)

    # ------------------------------------------------------------ the lobe
    def _weights(self) -> tuple[mi.Float, mi.Float]:
        return (dr.gather(mi.Float, self.anisotropy, mi.UInt32(0)),
                dr.gather(mi.Float, self.anisotropy, mi.UInt32(1)))

    def _distribution(self, weft: bool) -> mi.MicrofacetDistribution:
        """GGX of a thread in the warp's frame: narrow along +x (the warp), wide across; the
        weft's is the same turned by 90 degrees."""
        au, av = (self.across, self.along) if weft else (self.along, self.across)
        return mi.MicrofacetDistribution(mi.MicrofacetType.GGX, au, av, False)

    def _thread_frame(self, si):
        """``turn(v)``: local directions into the threads' frame (x along the warp)."""
        t = si.to_local(self.thread)
        length = dr.sqrt(dr.square(t.x) + dr.square(t.y))
        in_plane = length > _IN_PLANE_EPS
        c = dr.select(in_plane, t.x / dr.select(in_plane, length, 1.0), 1.0)
        s = dr.select(in_plane, t.y / dr.select(in_plane, length, 1.0), 0.0)
        return lambda v: mi.Vector3f(c * v.x + s * v.y, c * v.y - s * v.x, v.z)

    def single_scattering(self, wi: mi.Vector3f, wo: mi.Vector3f, weft: bool = False) -> mi.Float:
        """``f_s = D(h) G(wi, wo) / (4 cos_i cos_o)`` (1/sr) of the warp's lobe (the weft's with
        ``weft``), directions in the threads' frame; 0 where either is below the surface."""
        distribution = self._distribution(weft)
        h = dr.normalize(wi + wo)
        cos_i, cos_o = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
        valid = (cos_i > 0.0) & (cos_o > 0.0)
        f = distribution.eval(h) * distribution.G(wi, wo, h) / (4.0 * dr.select(valid, cos_i * cos_o, 1.0))
        return dr.select(valid & dr.isfinite(f), f, 0.0)

    def albedo(self, w: mi.Vector3f, weft: bool = False) -> mi.Float:
        """``E(w)``: the fraction of light from ``w`` (threads' frame) that the warp's (weft's)
        single-scattering lobe reflects, bilinear in the table of :func:`albedo_table`."""
        if weft:  # the weft's frame is the warp's turned by 90 degrees
            w = mi.Vector3f(w.y, w.x, w.z)
        theta = dr.acos(dr.clip(w.z, 0.0, 1.0)) * ((_N_THETA - 1) / (0.5 * dr.pi))
        phi = dr.atan2(dr.abs(w.y), dr.abs(w.x)) * ((_N_PHI - 1) / (0.5 * dr.pi))
        i = dr.clip(mi.UInt32(dr.floor(theta)), 0, _N_THETA - 2)
        j = dr.clip(mi.UInt32(dr.floor(phi)), 0, _N_PHI - 2)
        u = dr.clip(theta - mi.Float(i), 0.0, 1.0)
        v = dr.clip(phi - mi.Float(j), 0.0, 1.0)

        def at(di, dj):
            return dr.gather(mi.Float, self.table, (i + di) * _N_PHI + j + dj)

        return dr.lerp(dr.lerp(at(0, 0), at(0, 1), v), dr.lerp(at(1, 0), at(1, 1), v), u)

    def _lobes(self, si, wo: mi.Vector3f, a_warp: mi.Float, a_weft: mi.Float) -> mi.Float:
        """``a_warp f(warp) + a_weft f(weft)`` in 1/sr for local directions ``si.wi``, ``wo``
        (0 where either is below the surface), each ``f = f_s + f_ms``."""
        turn = self._thread_frame(si)
        wi_t, wo_t = turn(si.wi), turn(wo)
        valid = (mi.Frame3f.cos_theta(si.wi) > 0.0) & (mi.Frame3f.cos_theta(wo) > 0.0)
        total = []
        for weft in (False, True):
            multiple = (1.0 - self.albedo(wi_t, weft)) * (1.0 - self.albedo(wo_t, weft)) * self.ms_scale
            total.append(self.single_scattering(wi_t, wo_t, weft) + multiple)
        # Finite everywhere: at the null value the lobes enter as ``0 * lobes``.
        return dr.select(valid, a_warp * total[0] + a_weft * total[1], 0.0)

    # ------------------------------------------------------- BSDF interface
    def sample(self, ctx, si, sample1, sample2, active=True):
        cos_theta_i = mi.Frame3f.cos_theta(si.wi)
        bs = dr.zeros(mi.BSDFSample3f)
        active = active & (cos_theta_i > 0.0)
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return bs, mi.Color3f(0.0)
        bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
        bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        bs.sampled_component = mi.UInt32(0)
        value = self.reflectance.eval(si, active)
        if self.lobes:
            a_warp, a_weft = self._weights()
            # f cos_o / pdf, with pdf = cos_o / pi: rho at the null value exactly (rho * (1 + 0)).
            value = value * ((1.0 - a_warp - a_weft) + dr.pi * self._lobes(si, bs.wo, a_warp, a_weft))
        return bs, value & (active & (bs.pdf > 0.0))

    def eval(self, ctx, si, wo, active=True):
        value, _ = self.eval_pdf(ctx, si, wo, active)
        return value

    def pdf(self, ctx, si, wo, active=True):
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Float(0.0)
        cos_theta_i, cos_theta_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        pdf = mi.warp.square_to_cosine_hemisphere_pdf(wo)
        return dr.select((cos_theta_i > 0.0) & (cos_theta_o > 0.0), pdf, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Color3f(0.0), mi.Float(0.0)
        cos_theta_i, cos_theta_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        active = active & (cos_theta_i > 0.0) & (cos_theta_o > 0.0)
        value = self.reflectance.eval(si, active)
        if self.lobes:
            a_warp, a_weft = self._weights()
            # (rho / pi) * cos_o as Mitsuba's diffuse computes it, plus the lobes: at the null
            # value ((rho / pi) * 1 + rho * 0) * cos_o, the same bits.
            f = (value * dr.inv_pi * (1.0 - a_warp - a_weft)
                 + value * self._lobes(si, wo, a_warp, a_weft)) * cos_theta_o
        else:
            f = value * dr.inv_pi * cos_theta_o
        pdf = mi.warp.square_to_cosine_hemisphere_pdf(wo)
        return dr.select(active, f, 0.0), dr.select(active, pdf, 0.0)

    def traverse(self, callback):
        callback.put("reflectance", self.reflectance, mi.ParamFlags.Differentiable)
        callback.put("anisotropy", self.anisotropy, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        self._check_lobes()

    def to_string(self):
        return (f"DiffuseBSDF[reflectance={self.reflectance}, anisotropy={self.anisotropy}, "
                f"thread_direction={self.thread}]")


mi.register_bsdf(PLUGIN, lambda props: DiffuseBSDF(props))
