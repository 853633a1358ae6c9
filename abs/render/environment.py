"""Differentiable lat-long environment lighting with scale and rotation.

Why not evaluate Mitsuba's ``envmap`` directly: its ``to_world`` rotation is not differentiable.
Here the map is looked up with our own bilinear interpolation (matching Mitsuba's ``envmap`` value
for value, see ``tests/test_environment.py``), after rotating the query direction by an attached
rotation about the world +y axis (``rotation``) and an attached rotation vector about all three
axes (``orientation``, applied last: ``R(orientation) R_y(rotation) to_world``), so gradients
reach ``scale``, ``rotation``, ``orientation`` and the pixel data. At ``orientation = 0`` its
matrix is the identity exactly (:func:`~abs.render.rotation.rotation_matrix`), and multiplying
by it changes no bit (``1 m + 0 m' + 0 m''`` is ``m`` for finite entries), so the map is looked
up exactly as without it.

Importance sampling draws a pixel with probability proportional to its luminance times the solid
angle it covers, then a uniform point inside it. Sampling is detached from the parameters (the
sampled direction is a fixed point of the integration domain; only its radiance is attached), which
keeps the estimator's gradient unbiased.

Finite distance (``environment.inverse_distance`` = 1/R > 0): the map lies on a sphere of radius
R around ``center``. Light arriving at a point ``o`` from direction ``d`` left the sphere at
``o + t d``, so the map is looked up in the direction of that point from the centre (parallax).
With ``o' = o - center`` and ``b = o'.d`` that direction is

    q = inv * o' + (sqrt(1 - inv^2 (|o'|^2 - b^2)) - inv * b) * d,     inv = 1/R,

which is exactly ``d`` at ``inv = 0`` and has the first-order term ``o' - b d`` (the component of
``o'`` across the ray), so the derivative with respect to ``inv`` at infinity is not zero.
Sampling stays in direction space (the pdf of ``d``), so the estimators are unchanged.

Chrome Fresnel left in a light-probe map (``environment.probe_fresnel`` = ``c`` per channel):
a mirror ball's reflectance depends on the angle of incidence, so a probe map not divided by it
carries it: brighter in the directions the ball's rim shows (behind the ball as seen from the
probe camera), a few per cent darker, and differently per colour, over the wide band between
(a metal's reflectance dips below its normal-incidence value before it rises to 1 at grazing).
The light from map direction ``l`` is then

    L(l) = L_map(l) / (1 + c (F(cos_i) / F(1) - 1)),     cos_i = sqrt((1 + l.v) / 2),

``F`` the exact unpolarised Fresnel reflectance of the ball's metal (complex index
``probe_ior + i probe_k`` per channel; Mitsuba's ``fresnel_conductor``), ``cos_i`` the ball's
angle of incidence for ``l`` seen by a distant camera in direction ``v`` (``probe_view``, map
frame). ``c = 1``: the ball's reflectance left in whole; ``c = 0``: divided out, and the factor
is ``1 + 0 w = 1`` exactly, so the map is looked up as without it. (Schlick's ``(1 - cos_i)^5``
shape, the model before, rises monotonically and cannot render the dip, which is what lights a
scene whose cameras stood where the probe camera did; a colour matrix mimicked it better.)
Sampling ignores the factor (a pdf that differs from the light is still unbiased), and
:meth:`Environment.mitsuba_dict`'s emitter leaves it out.

Conventions (docs/conventions.md): Mitsuba's orientation, ``u = atan2(x, -z) / 2pi``,
``v = acos(y) / pi`` in the map's local frame; column centres at ``u = (i + 0.5) / W`` and row
centres at ``v = j / (H - 1)``, as Mitsuba's ``envmap`` interpolates.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.jit import from_numpy, in_use, opaque
from abs.render.rotation import rotation_matrix
from abs.scene.scene import CHROMIUM_IOR_RGB, CHROMIUM_K_RGB

__all__ = ["Environment"]


def _rotation_y(angle) -> mi.Matrix3f:
    c, s = dr.cos(angle), dr.sin(angle)
    return mi.Matrix3f(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)


def _rotation_np(r: np.ndarray) -> np.ndarray:
    """Rodrigues' rotation matrix of rotation vector ``r`` (radians), in numpy."""
    theta = float(np.linalg.norm(r))
    if theta == 0.0:
        return np.eye(3)
    k = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]]) / theta
    return np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)


class Environment:
    """An HDR lat-long environment map, at infinity or on a sphere of finite radius.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3)
        Linear RGB radiance (W/(m^2 sr) up to the map's calibration).
    scale : float
        Multiplier of the radiance (``environment.scale``).
    to_world : ndarray, shape (4, 4)
        Fixed orientation of the map (rotation part used).
    rotation : float
        Extra rotation about world +y in radians (``environment.rotation``).
    inverse_distance : float
        1 / radius of the map's sphere in 1/m (``environment.inverse_distance``; 0: at infinity).
    center : array-like, shape (3,)
        Centre of that sphere, world metres.
    orientation : array-like, shape (3,)
        Rotation vector (axis times angle, radians, world frame) applied after ``rotation``
        (``environment.orientation``; zeros: none).
    probe_fresnel : array-like, shape (3,)
        Fraction of the probe ball's angle-dependent reflectance left in the map, per R, G, B
        (``environment.probe_fresnel``; zeros: none; module docstring).
    probe_view : array-like, shape (3,)
        Direction from the ball towards the probe camera, map frame.
    probe_ior, probe_k : array-like, shape (3,)
        The ball's metal: real and imaginary parts of its complex index per R, G, B.
    """

    def __init__(self, rgb: np.ndarray, scale: float = 1.0, to_world: np.ndarray | None = None,
                 rotation: float = 0.0, inverse_distance: float = 0.0, center=(0.0, 0.0, 0.0),
                 orientation=(0.0, 0.0, 0.0), probe_fresnel=(0.0, 0.0, 0.0),
                 probe_view=(0.0, 0.0, 1.0), probe_ior=CHROMIUM_IOR_RGB, probe_k=CHROMIUM_K_RGB):
        rgb = np.ascontiguousarray(rgb, dtype=np.float32)
        self.height, self.width = rgb.shape[:2]
        self.data = mi.TensorXf(from_numpy(mi.Float, rgb), rgb.shape)
        # Opaque so that new values (every fit iteration) do not recompile kernels.
        self.scale = dr.opaque(mi.Float, scale)
        self.rotation = dr.opaque(mi.Float, rotation)
        self.inverse_distance = dr.opaque(mi.Float, inverse_distance)
        self.orientation = opaque(mi.Float, np.asarray(orientation, np.float32).ravel())
        self.probe_fresnel = opaque(mi.Float, np.asarray(probe_fresnel, np.float32).ravel())
        view = np.asarray(probe_view, np.float64).ravel()
        # Opaque, like every value here, so that scenes with other views reuse the kernels.
        self.probe_view = mi.Vector3f(*(dr.opaque(mi.Float, float(x)) for x in view / np.linalg.norm(view)))
        # The ball's metal per channel, and its reflectance at normal incidence (the reference).
        self.probe_metal = [mi.Complex2f(dr.opaque(mi.Float, float(n)), dr.opaque(mi.Float, float(k)))
                            for n, k in zip(np.ravel(probe_ior), np.ravel(probe_k))]
        self._probe_f0 = [mi.fresnel_conductor(mi.Float(1.0), eta) for eta in self.probe_metal]
        self.center = mi.Point3f(*[float(c) for c in center])
        m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=np.float64)
        self.to_world_np = m
        self._base = mi.Matrix3f(m[:3, :3].astype(np.float32))
        self._build_sampling(rgb)

    # ------------------------------------------------------------------ frames
    def _to_world(self, detach: bool = False) -> mi.Matrix3f:
        rotation = dr.detach(self.rotation) if detach else self.rotation
        r = dr.detach(self.orientation) if detach else self.orientation
        vector = mi.Vector3f(*(dr.gather(mi.Float, r, mi.UInt32(i)) for i in range(3)))
        return rotation_matrix(vector) @ (_rotation_y(rotation) @ self._base)

    def to_local(self, d: mi.Vector3f, detach: bool = False) -> mi.Vector3f:
        return self._to_world(detach).T @ d

    # ------------------------------------------------------------- evaluation
    def eval(self, d: mi.Vector3f, active=True, origin: mi.Point3f | None = None) -> mi.Color3f:
        """Radiance arriving at ``origin`` *from* world direction ``d`` (pointing away from the
        scene). ``origin`` matters only at a finite distance; ``None`` means the map at infinity."""
        if origin is not None:
            d = self.hit_direction(origin, d)
        v = dr.normalize(self.to_local(d))
        u = dr.atan2(v.x, -v.z) * dr.inv_two_pi
        u = u - dr.floor(u)
        t = dr.safe_acos(v.y) * dr.inv_pi
        light = self._bilinear(u, t, active) * self.scale
        return light / self._probe_fresnel(v) if self._probe_on else light

    @property
    def probe_fresnel(self) -> mi.Float:
        """``c`` per R, G, B (module docstring)."""
        return self._probe_c

    @probe_fresnel.setter
    def probe_fresnel(self, value: mi.Float) -> None:
        # At the null value (and not differentiated) lookups skip the factor: the map as it is,
        # bit for bit, without the three conductor Fresnel evaluations per lookup (about 5 % of
        # a render of the default scene).
        self._probe_c = value
        self._probe_on = in_use(value)

    def _probe_fresnel(self, v: mi.Vector3f) -> mi.Color3f:
        """``1 + c (F(cos_i) / F(1) - 1)`` for map-frame direction ``v`` (module docstring)."""
        cos_i = dr.safe_sqrt(0.5 * (1.0 + dr.dot(v, self.probe_view)))
        c = self.probe_fresnel
        return mi.Color3f(*(1.0 + dr.gather(mi.Float, c, mi.UInt32(i))
                            * (mi.fresnel_conductor(cos_i, eta) / f0 - 1.0)
                            for i, (eta, f0) in enumerate(zip(self.probe_metal, self._probe_f0))))

    def hit_direction(self, origin: mi.Point3f, d: mi.Vector3f) -> mi.Vector3f:
        """Direction from the centre to where the ray ``origin + t d`` (``d`` unit) leaves the
        map's sphere; ``d`` itself at infinite distance (see the module docstring)."""
        inv = self.inverse_distance
        o = origin - self.center
        b = dr.dot(o, d)
        across = dr.squared_norm(o) - dr.square(b)
        # Clamped: a ray starting outside the sphere and missing it sees the nearest point.
        root = dr.safe_sqrt(1.0 - dr.square(inv) * across)
        return inv * o + (root - inv * b) * d

    def _bilinear(self, u, t, active) -> mi.Color3f:
        w, h = self.width, self.height
        x = u * w - 0.5
        # Mitsuba's envmap puts row centres at t = i / (h - 1) (poles on the first and last rows)
        # but column centres at u = (i + 0.5) / w; we match it exactly.
        y = dr.clip(t * (h - 1), 0.0, h - 1.0)
        x0 = dr.floor(x)
        y0 = dr.minimum(dr.floor(y), h - 2) if h > 1 else dr.floor(y)
        fx, fy = x - x0, y - y0
        xi0 = mi.Int32(x0)
        xi0 = dr.select(xi0 < 0, xi0 + w, xi0)
        xi1 = dr.select(xi0 + 1 >= w, xi0 + 1 - w, xi0 + 1)
        yi0 = mi.Int32(y0)
        yi1 = dr.minimum(yi0 + 1, h - 1)
        flat = self.data.array

        def fetch(xi, yi):
            base = (yi * w + xi) * 3
            return mi.Color3f(dr.gather(mi.Float, flat, base, active),
                              dr.gather(mi.Float, flat, base + 1, active),
                              dr.gather(mi.Float, flat, base + 2, active))

        top = fetch(xi0, yi0) * (1.0 - fx) + fetch(xi1, yi0) * fx
        bottom = fetch(xi0, yi1) * (1.0 - fx) + fetch(xi1, yi1) * fx
        return top * (1.0 - fy) + bottom * fy

    # --------------------------------------------------------------- sampling
    def _build_sampling(self, rgb: np.ndarray) -> None:
        h, w = rgb.shape[:2]
        lum = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
        theta = (np.arange(h) + 0.5) / h * np.pi
        weight = np.maximum(lum, 0.0) * np.sin(theta)[:, None]
        # A floor keeps every direction sampleable, so MIS stays unbiased for dark pixels.
        weight = weight + 1e-3 * max(float(weight.mean()), 1e-12)
        self._pmf = weight / weight.sum()
        self._distribution = mi.DiscreteDistribution(from_numpy(mi.Float, self._pmf))
        self._pmf_flat = from_numpy(mi.Float, self._pmf)

    def sample(self, sample: mi.Point2f, active=True):
        """Sample a world direction towards the environment.

        Returns ``(d, pdf)``: detached direction and its solid-angle density (1/sr).
        """
        index, u_rest = self._distribution.sample_reuse(sample.x, active)
        w, h = self.width, self.height
        col = index % w
        row = index // w
        u = (mi.Float(col) + u_rest) / w
        t = (mi.Float(row) + sample.y) / h
        theta, phi = t * dr.pi, u * dr.two_pi
        st = dr.sin(theta)
        local = mi.Vector3f(st * dr.sin(phi), dr.cos(theta), -st * dr.cos(phi))
        d = dr.detach(self._to_world(detach=True)) @ local
        return d, self._pdf_local(u, t, st)

    def pdf(self, d: mi.Vector3f, active=True) -> mi.Float:
        """Solid-angle density (1/sr) of :meth:`sample` producing world direction ``d``."""
        v = dr.normalize(self.to_local(dr.detach(d), detach=True))
        u = dr.atan2(v.x, -v.z) * dr.inv_two_pi
        u = u - dr.floor(u)
        t = dr.safe_acos(v.y) * dr.inv_pi
        return self._pdf_local(u, t, dr.safe_sqrt(1.0 - dr.square(v.y)), active)

    def _pdf_local(self, u, t, sin_theta, active=True) -> mi.Float:
        w, h = self.width, self.height
        col = dr.minimum(mi.UInt32(u * w), w - 1)
        row = dr.minimum(mi.UInt32(t * h), h - 1)
        p = dr.gather(mi.Float, self._pmf_flat, row * w + col, active)
        # pmf spread uniformly over the pixel's (u, t) cell of area 1/(w h); d(omega) = 2 pi^2 sin dudt
        return dr.detach(dr.select(sin_theta > 1e-6, p * (w * h) / (2.0 * dr.square(dr.pi) * sin_theta), 0.0))

    def mitsuba_dict(self) -> dict:
        """An equivalent Mitsuba ``envmap`` emitter (for interoperability with stock integrators)."""
        m = self.to_world_np.copy()
        r = float(dr.detach(self.rotation)[0]) if dr.width(self.rotation) else 0.0
        c, s = np.cos(r), np.sin(r)
        rot = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])
        rot[:3, :3] = _rotation_np(np.asarray(dr.detach(self.orientation), np.float64)) @ rot[:3, :3]
        return {"type": "envmap", "bitmap": mi.Bitmap(np.asarray(self.data.numpy(), np.float32)),
                "scale": float(self.scale[0]), "to_world": mi.ScalarTransform4f(rot @ m)}
