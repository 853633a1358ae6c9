"""A Mitsuba BSDF that evaluates an isotropic BRDF table in the MERL layout, differentiably.

Plugin name ``abs_tabulated``. The table (3 × 90 × 90 × 180 values in 1/sr, MERL order, see
:mod:`abs.io.merl`) is one flat ``mi.Float`` exposed to ``mi.traverse`` under the key suffix
``table`` (e.g. ``"<bsdf id>.table"``), flagged differentiable: gradients reach the table
entries through the ``dr.gather`` calls of the trilinear lookup.

Scene description::

    {"type": "abs_tabulated", "filename": "gold.binary"}   # or no filename: all zeros

Lookup: the direction pair is converted to Rusinkiewicz angles (θh, θd, φd) with the light
direction (Mitsuba's ``wo``) as the "difference" vector, as MERL and NBRDF do. The angles map to
continuous table coordinates in which sample ``i`` sits at coordinate ``i`` exactly:

- θh → 90·√(θh / (π/2)), clamped to [0, 89],
- θd → 90·θd / (π/2), clamped to [0, 89],
- φd → 180·φd / π with φd folded into [0, π) by reciprocity (f(φd) = f(φd + π)) and wrapped
  periodically, so coordinate 179.5 blends samples 179 and 0.

The value is the trilinear blend of the 8 neighbouring samples. Swapping ``wi`` and ``wo``
turns φd into φd ± π, which the fold maps to the same coordinates: the BSDF is reciprocal.
"""

from __future__ import annotations

import sys
from pathlib import Path

from abs.render.variant import set_variant

# A Python plugin subclasses the active variant's mi.BSDF, so a variant must be set before the
# class is defined; set_variant also points Dr.Jit at a usable libLLVM before mitsuba loads.
if "mitsuba" not in sys.modules or sys.modules["mitsuba"].variant() is None:
    set_variant()

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
from abs.io.merl import MERL_SHAPE, MERL_SIZE, read_merl  # noqa: E402
from abs.render.jit import from_numpy  # noqa: E402

__all__ = ["PLUGIN_NAME", "TABLE_KEY", "TabulatedBSDF", "CosineSampledTable", "cosine_sampled",
           "register", "rusinkiewicz_angles", "table_corners"]

PLUGIN_NAME = "abs_tabulated"
TABLE_KEY = "table"
"""Suffix of the table's key in ``mi.traverse``: ``"<bsdf id>.table"``."""

_N_TH, _N_TD, _N_PD = MERL_SHAPE[1:]
_CHANNEL_STRIDE = _N_TH * _N_TD * _N_PD
# Below this sin θh the half vector is treated as the normal (φh = 0), which avoids 0/0.
_SIN_EPS = 1e-7


def rusinkiewicz_angles(wi: mi.Vector3f, wo: mi.Vector3f) -> tuple[mi.Float, mi.Float, mi.Float]:
    """Rusinkiewicz angles of a pair of local directions (z = normal).

    Parameters
    ----------
    wi, wo : mi.Vector3f
        Unit directions in the local shading frame. ``wo`` becomes the difference vector.

    Returns
    -------
    theta_h, theta_d, phi_d : mi.Float
        Half-vector elevation in [0, π], difference elevation in [0, π] and difference azimuth
        in (-π, π], radians.
    """
    h = dr.normalize(wi + wo)
    sin_th = dr.sqrt(dr.maximum(h.x * h.x + h.y * h.y, 0.0))
    cos_th = h.z
    theta_h = dr.atan2(sin_th, cos_th)

    # Rotate wo by -φh about z, then by -θh about y: the half vector becomes +z.
    valid = sin_th > _SIN_EPS
    inv = dr.select(valid, dr.rcp(sin_th), 0.0)
    cos_ph = dr.select(valid, h.x * inv, 1.0)
    sin_ph = h.y * inv
    x1 = wo.x * cos_ph + wo.y * sin_ph
    y1 = wo.y * cos_ph - wo.x * sin_ph
    dx = x1 * cos_th - wo.z * sin_th
    dz = x1 * sin_th + wo.z * cos_th
    dy = y1

    theta_d = dr.atan2(dr.sqrt(dx * dx + dy * dy), dz)
    phi_d = dr.atan2(dy, dx)
    return theta_h, theta_d, phi_d


def _axis(coord: mi.Float, n: int) -> tuple[mi.UInt32, mi.UInt32, mi.Float]:
    """Lower/upper sample index and blend weight on a clamped axis of ``n`` samples."""
    coord = dr.clip(coord, 0.0, n - 1.0)
    lo = dr.minimum(mi.UInt32(dr.floor(coord)), n - 2)
    return lo, lo + 1, coord - mi.Float(lo)


def table_corners(wi: mi.Vector3f, wo: mi.Vector3f) -> list[tuple[mi.UInt32, mi.Float]]:
    """The 8 table entries around a direction pair and their trilinear weights.

    Parameters
    ----------
    wi, wo : mi.Vector3f
        Unit local directions (module docstring: ``wo`` is the difference vector).

    Returns
    -------
    list of (mi.UInt32, mi.Float)
        Entry index within one channel's block (θh-major, then θd, then φd) and its weight; the
        weights sum to 1.
    """
    theta_h, theta_d, phi_d = rusinkiewicz_angles(wi, wo)
    phi_d = dr.select(phi_d < 0.0, phi_d + dr.pi, phi_d)

    h0, h1, th = _axis(_N_TH * dr.sqrt(dr.maximum(theta_h, 0.0) * (2.0 / dr.pi)), _N_TH)
    d0, d1, td = _axis(theta_d * (_N_TD * 2.0 / dr.pi), _N_TD)
    # φd is periodic over π: wrap instead of clamp.
    p_coord = dr.clip(phi_d * (_N_PD / dr.pi), 0.0, float(_N_PD))
    p_floor = dr.minimum(mi.UInt32(dr.floor(p_coord)), _N_PD)
    tp = p_coord - mi.Float(p_floor)
    p0 = p_floor % _N_PD
    p1 = (p_floor + 1) % _N_PD

    corners = []
    for hi, wh in ((h0, 1.0 - th), (h1, th)):
        for di, wd in ((d0, 1.0 - td), (d1, td)):
            row = (hi * _N_TD + di) * _N_PD
            for pi, wp in ((p0, 1.0 - tp), (p1, tp)):
                corners.append((row + pi, wh * wd * wp))
    return corners


class CosineSampledTable:
    """``eval``, ``pdf``, ``eval_pdf`` and ``sample`` of a one-sided BRDF known by lookup.

    For a ``mi.BSDF`` subclass of the active variant that defines ``_lookup(si, wo, active)``
    (the BRDF in 1/sr, no cosine, as ``mi.Spectrum``): this plugin, and its spectral port in
    :mod:`abs.appearance.spectral_tabulated`, which must subclass a spectral variant's
    ``mi.BSDF`` in another process. A nanobind type takes one base only, so the plugins take
    these methods as class attributes (:func:`cosine_sampled`) rather than inheriting them. ``eval`` returns f · cos θo (Mitsuba's convention); sampling is
    cosine-weighted over the upper hemisphere, so a sample's weight is f · π; both directions
    must be above the horizon.
    """

    def _eval(self, si, wo, active):
        """f · cos θo and the mask of pairs with both directions above the horizon."""
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0.0) & (cos_o > 0.0)
        value = self._lookup(si, wo, active) * cos_o
        return dr.select(active, value, 0.0), active

    def eval(self, ctx, si, wo, active=True):
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Spectrum(0.0)
        return self._eval(si, wo, mi.Bool(active))[0]

    def pdf(self, ctx, si, wo, active=True):
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Float(0.0)
        active = mi.Bool(active) & (mi.Frame3f.cos_theta(si.wi) > 0.0)
        active &= mi.Frame3f.cos_theta(wo) > 0.0
        return dr.select(active, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return mi.Spectrum(0.0), mi.Float(0.0)
        value, valid = self._eval(si, wo, mi.Bool(active))
        return value, dr.select(valid, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        bs = dr.zeros(mi.BSDFSample3f)
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection):
            return bs, mi.Spectrum(0.0)
        wo = mi.warp.square_to_cosine_hemisphere(sample2)
        value, valid = self._eval(si, wo, mi.Bool(active))
        pdf = mi.warp.square_to_cosine_hemisphere_pdf(wo)
        valid &= pdf > 0.0
        bs.wo = wo
        bs.pdf = dr.select(valid, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        bs.sampled_component = mi.UInt32(0)
        return bs, dr.select(valid, value / dr.maximum(pdf, 1e-20), 0.0)


def cosine_sampled(cls):
    """Class decorator: give the ``mi.BSDF`` subclass ``cls`` (which defines ``_lookup``) the
    methods of :class:`CosineSampledTable`."""
    for name in ("_eval", "eval", "pdf", "eval_pdf", "sample"):
        setattr(cls, name, getattr(CosineSampledTable, name))
    return cls


@cosine_sampled
class TabulatedBSDF(mi.BSDF):
    """Isotropic, reciprocal, front-side BRDF given by a MERL-layout table (1/sr).

    Parameters
    ----------
    props : mi.Properties
        ``filename`` (optional): a MERL ``.binary`` file, resolved with Mitsuba's file resolver.
        Without it the table starts at zero and is meant to be set through ``mi.traverse``.

    Notes
    -----
    ``eval`` returns f(wi, wo) · cos θo (Mitsuba's convention); sampling is cosine-weighted over
    the upper hemisphere, so the sample weight is f · π. The flags are
    ``DiffuseReflection | FrontSide``: the BSDF is not delta-like, so integrators also sample
    emitters, and it is one-sided (0 when either direction is below the horizon).
    """

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        if "filename" in props:
            filename = str(props["filename"])
            # resolve() returns a mi.filesystem.path, which pathlib does not accept.
            path = Path(str(mi.file_resolver().resolve(filename)))
            self.filename: str | None = str(path)
            self.table = from_numpy(mi.Float, read_merl(path))
        else:
            self.filename = None
            self.table = dr.zeros(mi.Float, MERL_SIZE)
        # An opaque table is a real buffer, not a constant folded into every kernel.
        dr.make_opaque(self.table)
        flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [flags]
        self.m_flags = flags

    # -- parameters -----------------------------------------------------------------------------
    def traverse(self, callback: mi.TraversalCallback) -> None:
        callback.put(TABLE_KEY, self.table, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys: list[str]) -> None:
        width = dr.width(self.table)
        if width != MERL_SIZE:
            raise ValueError(
                f"{PLUGIN_NAME}: '{TABLE_KEY}' must hold {MERL_SIZE} values (3×90×90×180), got {width}"
            )
        dr.make_opaque(self.table)

    # -- evaluation -----------------------------------------------------------------------------
    def _lookup(self, si: mi.SurfaceInteraction3f, wo: mi.Vector3f,
                active: mi.Bool) -> mi.Color3f:
        """Trilinearly interpolated BRDF (1/sr, no cosine) for local directions."""
        corners = table_corners(si.wi, wo)

        channels = []
        for c in range(3):
            value = mi.Float(0.0)
            for index, weight in corners:
                value += weight * dr.gather(mi.Float, self.table, index + c * _CHANNEL_STRIDE, active)
            channels.append(value)
        return mi.Color3f(channels[0], channels[1], channels[2])

    def to_string(self) -> str:
        source = self.filename if self.filename is not None else "set via mi.traverse"
        return f"TabulatedBSDF[table={source}]"


_REGISTERED: set[str] = set()


def register() -> None:
    """Register the ``abs_tabulated`` plugin for the active variant (safe to call repeatedly)."""
    variant = mi.variant()
    if variant in _REGISTERED:
        return
    if variant != _CLASS_VARIANT:
        raise RuntimeError(
            f"{__name__} was imported under variant {_CLASS_VARIANT!r} but {variant!r} is active; "
            "Python plugins subclass a variant's mi.BSDF, so choose the variant before importing"
        )
    mi.register_bsdf(PLUGIN_NAME, lambda props: TabulatedBSDF(props))
    _REGISTERED.add(variant)


_CLASS_VARIANT = mi.variant()
register()
