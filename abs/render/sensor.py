"""The camera sensor applied to rendered radiance: an error of the camera matrix, vignetting,
stray light, a colour matrix, the blur of the photographs' processing and a non-linear response.

Applied to every rendering after the path tracer (in :meth:`CompiledScene.render`), in Dr.Jit, so
images stay differentiable with respect to the sensor's parameters and to everything upstream.
The order follows the light: the photographs' camera matrix differs from the calibrated one
(``intrinsics_offset``: the image lands shifted and scaled on the sensor), the lens attenuates
the image towards its corners (vignetting), light scattered inside the lens adds a veil (stray
light), the sensor's colour filters mix the channels of what reaches it (colour matrix), then the
photographs' processing blurs each channel (demosaicing and resampling in a capture build:
``camera.blur_px``, not a fitted parameter), and the sensor converts each channel's irradiance to
values (response)::

    out_c = (G_c * sum_j M_cj (V(r) L'_j + s_j)) ** gamma_c,     V(r) = 1 + k1 r^2 + k2 r^4,
    L'(u) = L(u + d(u)),     d(u) = -(dc + e (u - c)) / (1 + e),     e = df / f

with ``r`` the distance of the point on the image plane from the principal point in units of the
focal length (OpenCV normalised coordinates), ``M`` the 3x3 colour matrix (rendering RGB to
photograph RGB), and ``L(u + d(u))`` the rendering resampled (Catmull-Rom cubics) where the calibrated camera
sees what the photographs' camera, with principal point ``c + dc`` and focal lengths scaled by
``1 + e``, sees at pixel ``u`` (``K K'^-1 u``: exact for a pinhole, skew included, since scaling
the focal lengths scales the skew with them). A camera turned about its centre (``camera_turn``,
a rotation vector ``w``: a point at ``x`` in the calibrated camera's frame is at ``R(w) x`` in the
photographs') sees the calibrated camera's image through the homography ``K R(w)^T K'^-1``, also
exact for a pinhole; to first order it moves the image like a principal-point shift of ``f``
times the angle, but the shift grows towards the image's edges by about ``(x / f)^2`` of itself,
which a shift cannot follow. A translation (parallax) is not an image warp and is not modelled.
The colour matrix sits **before** the response: a camera mixes colours in its linear signal (filter
cross-talk, white balance, its colour-correction matrix), and any tone curve comes after. Stray
light is light reaching the sensor, so it goes through ``M`` too. ``G_c *`` is a convolution with a
Gaussian of standard deviation ``blur_px[c]`` (:func:`blur_kernel`): a capture build demosaics and
resamples the photographs' camera RGB, so the blur acts after the colour mixing, and demosaicing
works on linear values (a camera's own processor demosaics its raw data before any tone curve), so
before the response. It is left out entirely when every ``blur_px`` is 0.

Every operation is exact at its null value (``dc = df = 0``: the displacement is ``-0``, the
sample sits on the pixel centre with Catmull-Rom weights 0, 1, 0, 0, ``L * 1 + L' * 0 ...``; ``k = 0``: ``L * 1``;
``s = 0``: ``+ 0``; ``M = I``: ``1 x_c + 0 x_j + 0 x_k``, where the products with 0 are +-0 and adding them to
``x_c`` leaves it unchanged for any finite ``x``; ``gamma = 1``: ``x * exp(0)``), so a sensor at
its null values returns the rendering bit for bit on a camera without ``blur_px``.

Downsampled cameras (``Camera.block > 1``) compare box averages of fine photograph pixels, each
vignetted at its own centre; the falloff is linear in ``k``, so the block average of ``r^2`` and
``r^4`` over the fine pixel centres gives exactly that average. The colour matrix is linear too,
so it commutes with the block average. The resampling works on the rendered (block) pixels, with
the offsets converted to them (``dc / block``; ``e`` is a ratio), so on a downsampled camera it
interpolates between block averages rather than averaging resampled fine pixels. Near the image border the shifted samples are clamped to the edge pixels: what lies
outside the rendered frame is not rendered.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.camera import Camera
from abs.render.jit import from_numpy, opaque

__all__ = ["Sensor", "blur_kernel", "radial_moments"]

# Below this value the logarithm in the response is clamped (a black pixel stays black).
_TINY = 1e-30


def _catmull_rom(t):
    """Catmull-Rom weights of the samples at -1, 0, 1, 2 for a point ``t`` in [0, 1) past sample 0.

    A cubic rather than bilinear interpolation so that the image is continuously differentiable
    in the offset: at the null value every sample sits on a pixel centre, where a bilinear
    interpolant has a kink and its derivative would be one-sided; Catmull-Rom's is the image's
    central difference there. At ``t = 0`` the weights are exactly 0, 1, 0, 0.
    """
    t2 = t * t
    t3 = t2 * t
    return (0.5 * (2.0 * t2 - t3 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (4.0 * t2 - 3.0 * t3 + t), 0.5 * (t3 - t2))


def radial_moments(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Block averages of ``r^2`` and ``r^4`` over each pixel's fine pixel centres.

    Parameters
    ----------
    camera : Camera
        A camera, possibly downsampled (``block`` fine pixels per pixel and axis).

    Returns
    -------
    r2, r4 : ndarray, shape (height, width)
        Dimensionless (``r`` in units of the focal length).
    """
    b = camera.block
    # Fine camera: K_fine = S^-1 K (see abs.model.downsampling.downsample_camera).
    shift = -(b - 1) / (2.0 * b)
    S = np.array([[1.0 / b, 0.0, shift], [0.0, 1.0 / b, shift], [0.0, 0.0, 1.0]])
    k_fine = np.linalg.solve(S, camera.K)
    v, u = np.mgrid[0:camera.height * b, 0:camera.width * b].astype(np.float64)
    kinv = np.linalg.inv(k_fine)
    x = kinv[0, 0] * u + kinv[0, 1] * v + kinv[0, 2]
    y = kinv[1, 0] * u + kinv[1, 1] * v + kinv[1, 2]
    z = kinv[2, 0] * u + kinv[2, 1] * v + kinv[2, 2]
    r2 = (x / z) ** 2 + (y / z) ** 2

    def block_mean(a):
        return a.reshape(camera.height, b, camera.width, b).mean(axis=(1, 3))

    return block_mean(r2), block_mean(r2 * r2)


def _lanes(camera: Camera):
    """``(width, height, pixel, channel)`` of the (H, W, 3) image's lanes as ``Int32``: the
    camera's numbers enter as opaque values, not literals, so that another view, size or block
    reuses the compiled kernels (tests/test_jit.py)."""
    h, w = camera.height, camera.width
    lane = dr.arange(mi.UInt32, h * w * 3)
    pixel = mi.Int32(lane // 3)
    return dr.opaque(mi.Int32, w), dr.opaque(mi.Int32, h), pixel, mi.Int32(lane) - 3 * pixel


def blur_kernel(sigma_px: float) -> np.ndarray:
    """Symmetric weights on the integer offsets ``-r .. r`` whose variance is ``sigma_px**2``.

    A sampled Gaussian ``exp(-k^2 / 2 s^2)``, normalised, with ``s`` chosen (by bisection) so that
    the discrete kernel's variance is exactly ``sigma_px**2``: for the sub-pixel blurs of a
    capture's processing, a Gaussian sampled at ``s = sigma_px`` would have the wrong variance
    (about 0.25 px^2 instead of 0.16 at ``sigma_px = 0.4``), and the variance is what sets the
    blur's effect on low spatial frequencies. ``r = max(1, ceil(3 sigma_px))``.

    Parameters
    ----------
    sigma_px : float
        Standard deviation in pixels, >= 0 (0: the identity ``[1]``).

    Returns
    -------
    ndarray, shape (2 r + 1,)
        Non-negative weights summing to 1.
    """
    if not sigma_px >= 0 or not np.isfinite(sigma_px):
        raise ValueError(f"blur must be a finite standard deviation >= 0 pixels, got {sigma_px}")
    if sigma_px == 0:
        return np.ones(1)
    r = max(1, int(np.ceil(3.0 * sigma_px)))
    k = np.arange(-r, r + 1, dtype=np.float64)

    def kernel(s):
        g = np.exp(-0.5 * (k / s) ** 2)
        return g / g.sum()

    lo, hi = 1e-3, 4.0 * sigma_px + 1.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.sum(kernel(mid) * k * k) < sigma_px ** 2 else (lo, mid)
    return kernel(0.5 * (lo + hi))


class Sensor:
    """The sensor's parameters as Dr.Jit arrays (any of them may be attached to the AD graph).

    Parameters
    ----------
    vignetting : array-like, shape (2,)
        ``[k1, k2]`` (dimensionless).
    response : array-like, shape (3,)
        Exponent per R, G, B.
    stray_light : array-like, shape (3,)
        Offset per R, G, B in radiance units.
    colour_matrix : array-like, shape (9,), optional
        The 3x3 matrix from rendering RGB to photograph RGB, row-major (dimensionless); the
        identity when left out.
    intrinsics_offset : array-like, shape (3,), optional
        ``[dcx, dcy, dfx]`` in pixels of the full-resolution photographs: the photographs'
        principal point minus the calibrated one, and their focal length ``fx`` minus the
        calibrated one (``fy`` and the skew scale by the same ratio); zeros when left out.
    camera_turn : array-like, shape (3,), optional
        Rotation vector (radians, camera frame) of the photographs' cameras against the
        calibrated poses (:class:`~abs.scene.scene.SensorSpec`); zeros when left out.
    """

    def __init__(self, vignetting, response, stray_light, colour_matrix=None, intrinsics_offset=None,
                 camera_turn=None):
        self.vignetting = opaque(mi.Float, np.asarray(vignetting, np.float32))
        self.response = opaque(mi.Float, np.asarray(response, np.float32))
        self.stray_light = opaque(mi.Float, np.asarray(stray_light, np.float32))
        matrix = np.eye(3).ravel() if colour_matrix is None else colour_matrix
        self.colour_matrix = opaque(mi.Float, np.asarray(matrix, np.float32).ravel())
        offset = np.zeros(3) if intrinsics_offset is None else intrinsics_offset
        self.intrinsics_offset = opaque(mi.Float, np.asarray(offset, np.float32).ravel())
        turn = np.zeros(3) if camera_turn is None else camera_turn
        self.camera_turn = opaque(mi.Float, np.asarray(turn, np.float32).ravel())

    def is_linear(self) -> bool:
        """Whether the output is affine in the radiance with a fixed derivative: the response is 1
        in every channel and no sensor parameter has gradients enabled. The adjoint of
        :meth:`apply` is then the same at every image (what lets a batched gradient skip
        rendering the whole image first, :meth:`CompiledScene.render_backward`)."""
        arrays = (self.vignetting, self.response, self.stray_light, self.colour_matrix,
                  self.intrinsics_offset, self.camera_turn)
        if any(dr.grad_enabled(a) for a in arrays):
            return False
        return bool(np.all(self.response.numpy() == 1.0))

    def apply(self, image: mi.TensorXf, camera: Camera) -> mi.TensorXf:
        """The sensor's output for rendered radiance ``image`` (height, width, 3) of ``camera``."""
        h, w = camera.height, camera.width
        flat = self._resample(image.array, camera)
        r2, r4 = radial_moments(camera)
        # One entry per (pixel, channel) lane, in the image's (H, W, 3) memory order.
        r2 = from_numpy(mi.Float, np.repeat(r2.ravel(), 3))
        r4 = from_numpy(mi.Float, np.repeat(r4.ravel(), 3))
        channel = dr.arange(mi.UInt32, h * w * 3) % 3
        k1 = dr.gather(mi.Float, self.vignetting, mi.UInt32(0))
        k2 = dr.gather(mi.Float, self.vignetting, mi.UInt32(1))
        veiled = flat * (1.0 + k1 * r2 + k2 * r4) + dr.gather(mi.Float, self.stray_light, channel)
        mixed = self._blur(self._mix(veiled, channel), camera)
        gamma = dr.gather(mi.Float, self.response, channel)
        # x ** gamma written as x * x ** (gamma - 1): exactly x at gamma = 1, with the derivative
        # x log x there, and no NaN at x = 0.
        log_x = dr.log(dr.maximum(mixed, _TINY))
        out = mixed * dr.exp((gamma - 1.0) * log_x)
        return mi.TensorXf(out, (h, w, 3))

    def _resample(self, flat: mi.Float, camera: Camera) -> mi.Float:
        """The (H, W, 3) image ``flat`` as the photographs' camera (``intrinsics_offset``,
        ``camera_turn``) sees it:
        each pixel interpolated at ``u + d(u)`` (module docstring) by Catmull-Rom cubics,
        indices clamped to the frame."""
        b = camera.block
        width, height, pixel, channel = _lanes(camera)
        u = mi.Float(pixel % width)
        v = mi.Float(pixel // width)
        per_block = dr.opaque(mi.Float, 1.0 / b)
        dcx = dr.gather(mi.Float, self.intrinsics_offset, mi.UInt32(0)) * per_block
        dcy = dr.gather(mi.Float, self.intrinsics_offset, mi.UInt32(1)) * per_block
        # The focal error as a ratio: the same on the fine and the block pixels.
        e = dr.gather(mi.Float, self.intrinsics_offset, mi.UInt32(2)) / dr.opaque(mi.Float, camera.K[0, 0] * b)
        cx, cy = dr.opaque(mi.Float, camera.K[0, 2]), dr.opaque(mi.Float, camera.K[1, 2])
        fx, fy = dr.opaque(mi.Float, camera.K[0, 0]), dr.opaque(mi.Float, camera.K[1, 1])
        skew = dr.opaque(mi.Float, camera.K[0, 1])
        # Written as a displacement added to the pixel's own coordinate, so that at the null
        # value the sample is the pixel centre exactly (u + -0 = u; ``cx + (u - cx)`` need not be).
        # The offset alone moves the pixel by (du, dv) (``K K'^-1``); in normalised coordinates
        # (A: K's 2x2 part) the photographs' ray is (x0 + px, y0 + py, 1) with (px, py) =
        # A^-1 (du, dv), turned into the calibrated frame by R(w)^T = R(-w) and projected; the
        # projection less (x0, y0), mapped back by A, is the displacement.
        du = -(dcx + e * (u - cx)) / (1.0 + e)
        dv = -(dcy + e * (v - cy)) / (1.0 + e)
        y0 = (v - cy) / fy
        x0 = (u - cx - skew * y0) / fx
        py = dv / fy
        px = (du - skew * py) / fx
        dx, dy = self._turned(x0, y0, px, py)
        x = dr.clip(u + (fx * dx + skew * dy), 0.0, mi.Float(width - 1))
        y = dr.clip(v + fy * dy, 0.0, mi.Float(height - 1))
        x0, y0 = dr.floor(x), dr.floor(y)
        wx, wy = _catmull_rom(x - x0), _catmull_rom(y - y0)
        i0, j0 = mi.Int32(x0), mi.Int32(y0)
        out = None
        for n in range(4):
            j = dr.clip(j0 + (n - 1), 0, height - 1)
            row = None
            for m in range(4):
                i = dr.clip(i0 + (m - 1), 0, width - 1)
                term = wx[m] * dr.gather(mi.Float, flat, mi.UInt32(3 * (j * width + i) + channel))
                row = term if row is None else row + term
            out = wy[n] * row if out is None else out + wy[n] * row
        return out

    def _turned(self, x0, y0, px, py):
        """``(X / Z - x0, Y / Z - y0)`` for ``(X, Y, Z) = R(-w) (x0 + px, y0 + py, 1)``, ``w``
        the camera turn: Rodrigues' formula with ``sin t / t`` and
        ``(1 - cos t) / t^2`` to second order in ``t = |w|`` (the error, ``t^4 / 120``, is below
        1e-6 within the bounds of 0.1 rad). Every term is a product with a component of ``w``,
        so at ``w = 0`` the result is ``(px, py)`` exactly."""
        w = [dr.gather(mi.Float, self.camera_turn, mi.UInt32(i)) for i in range(3)]
        t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
        sinc, versinc = 1.0 - t2 / 6.0, 0.5 - t2 / 24.0
        d = (x0 + px, y0 + py, 1.0)
        # R(-w) d = d - sinc (w x d) + versinc w x (w x d).
        a = (w[1] * d[2] - w[2] * d[1], w[2] * d[0] - w[0] * d[2], w[0] * d[1] - w[1] * d[0])
        b = (w[1] * a[2] - w[2] * a[1], w[2] * a[0] - w[0] * a[2], w[0] * a[1] - w[1] * a[0])
        extra = [versinc * b[i] - sinc * a[i] for i in range(3)]
        z = 1.0 + extra[2]
        return (px + extra[0] - extra[2] * x0) / z, (py + extra[1] - extra[2] * y0) / z

    def _blur(self, flat: mi.Float, camera: Camera) -> mi.Float:
        """The (H, W, 3) image ``flat`` blurred by the camera's point-spread function
        (``camera.blur_px``, full-resolution pixels, per channel): separable kernels of
        :func:`blur_kernel` on the rendered pixels (``blur_px / block``: blurring and block
        averaging are both convolutions, so they commute), edge pixels repeated at the border.
        The image itself when every channel's blur is 0."""
        sigma = np.asarray(camera.blur_px, np.float64) / camera.block
        if not np.any(sigma > 0):
            return flat
        kernels = [blur_kernel(s) for s in sigma]
        radius = max(len(k) for k in kernels) // 2
        # One row of 2 radius + 1 weights per channel, shorter kernels padded with zeros.
        table = np.zeros((3, 2 * radius + 1))
        for c, k in enumerate(kernels):
            pad = radius - len(k) // 2
            table[c, pad:pad + len(k)] = k
        weights = opaque(mi.Float, table.ravel().astype(np.float32))
        width, height, pixel, channel = _lanes(camera)
        x, y = pixel % width, pixel // width
        for along_x in (True, False):
            out = None
            for m in range(2 * radius + 1):
                weight = dr.gather(mi.Float, weights, mi.UInt32(channel * (2 * radius + 1) + m))
                if along_x:
                    i, j = dr.clip(x + (m - radius), 0, width - 1), y
                else:
                    i, j = x, dr.clip(y + (m - radius), 0, height - 1)
                term = weight * dr.gather(mi.Float, flat, mi.UInt32(3 * (j * width + i) + channel))
                out = term if out is None else out + term
            flat = out
        return flat

    def _mix(self, flat: mi.Float, channel: mi.UInt32) -> mi.Float:
        """``sum_j M_cj x_j`` for every (pixel, channel ``c``) lane of the (H, W, 3) image
        ``flat``."""
        base = dr.arange(mi.UInt32, dr.width(flat)) - channel  # the lane of the pixel's R
        out = None
        for j in range(3):
            # Sum of M_c0 x_0 + M_c1 x_1 + M_c2 x_2 in a fixed order: at M = I each product off
            # the diagonal is +-0 and the diagonal one is x_c itself, so the sum is x_c exactly.
            m = dr.gather(mi.Float, self.colour_matrix, 3 * channel + j)
            term = m * dr.gather(mi.Float, flat, base + j)
            out = term if out is None else out + term
        return out
