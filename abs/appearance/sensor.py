"""The sensor step: a filter that acts on a pixel's radiance and image position, not on θ.

A camera (and a renderer's exposure, white balance or tone curve) transforms every pixel the same
way whatever the material: the lens darkens the image towards its corners (vignetting), the
sensor's colour processing mixes the channels, and its response compresses the radiance. None of
these depend on θ or on the material class, so per-class θ statistics (α, λ, ψ) can only imitate
them where the characterisation's spheres happened to sit and at the brightness they happened to
have; the benchmark measured that the residual per-pixel error of the simulated camera is exactly
there (docs/appearance.md, "Where the per-pixel error comes from"). So this step models them
directly, in the order light meets them::

    B(p) = f_k( (M (v(r) A(p)))_k ),   v(r) = 1 + c1 r² + c2 r⁴

with ``A`` renderer A's linear RGB, ``r`` the pixel's distance from the image centre over the
half-diagonal (0 at the centre, 1 in a corner), ``M`` a 3x3 colour matrix whose rows sum to one
(white stays white, so the overall level belongs to ``f``), and ``f_k`` a per-channel monotone
response: piecewise linear in log10 radiance between knots spread over the data's range, with
positive slopes (so it is invertible, and can neither reorder nor fold two radiances together).
A pure per-channel gain ``g`` is ``v = 1``, ``M = I`` and ``f_k(x) = g_k x`` (slope 1 in log-log).

It is fitted on the characterisation design itself: both renderers render the same scenes with
the same camera, so their images correspond pixel for pixel. Each characterisation stores its
images' means over a coarse grid of equal blocks (``Characterisation.blocks``, every pixel of the
image: walls, floor and sphere, so every image position and many colours are seen); block means
average the Monte-Carlo noise that would otherwise bias a fit on noisy pixels. The fit minimises
the soft-L1 (robust) difference of log10 radiance, so a dark block counts as much as a bright one,
and blocks that straddle an edge (whose mean through a curve is not the curve of the mean) do not
pull the fit. Blocks darker than :data:`DARK_FLOOR` in either image are left out (their log is
mostly noise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from abs.errors import InputError

__all__ = ["Sensor", "fit_sensor", "block_means", "block_radius2", "image_radius2", "BLOCK_GRID",
           "DARK_FLOOR"]

BLOCK_GRID = 16
"""Blocks per image side in ``Characterisation.blocks`` (a 64-pixel image: blocks of 4x4)."""

DARK_FLOOR = 1e-3
"""Blocks darker than this (linear radiance) in any channel are not fitted."""

_N_KNOTS = 9  # response knots over the data's log range: 4-6 per decade at the benchmark's range
_SMOOTH = 0.05  # weight of the slopes' second differences (keeps knots with little data tame)
_ROBUST_SCALE = 0.02  # soft-L1 transition, log10 units (about 5 %): past it a block counts less
_PRIOR = 0.03  # weight pulling vignetting and the matrix's off-diagonals to 0: where the design's
# colours or positions cannot tell them apart (a few scenes, one wall colour), the fit stays the
# simplest sensor instead of wandering; with the full design it moves them by well under 1 %.
_MAX_NFEV = 120  # evaluations (each with a numerical Jacobian): the benchmark's fits converge in 30-70


@dataclass(frozen=True)
class Sensor:
    """A fitted sensor step (see the module docstring).

    Attributes
    ----------
    vignetting : np.ndarray
        ``(2,)``: ``c1, c2`` of ``v(r) = 1 + c1 r² + c2 r⁴`` (dimensionless; r in half-diagonals).
    matrix : np.ndarray
        ``(3, 3)`` colour matrix, rows summing to 1, applied as ``M @ rgb``.
    knots : np.ndarray
        ``(K,)`` log10 linear radiance (after vignetting and matrix) where the response is given.
    response : np.ndarray
        ``(3, K)`` log10 of the output at the knots, per channel; linear in between, and beyond
        the ends continued with the end segments' slopes.
    """

    vignetting: np.ndarray
    matrix: np.ndarray
    knots: np.ndarray
    response: np.ndarray

    def curve(self, x: np.ndarray) -> np.ndarray:
        """``f_k`` of ``x (..., 3)`` (linear radiance after vignetting and matrix)."""
        return 10.0 ** _log_curve(np.log10(np.maximum(x, _TINY)), self.knots, self.response)

    def apply(self, image: np.ndarray) -> np.ndarray:
        """``image (h, w, 3)`` linear RGB of renderer A as renderer B's sensor would show it."""
        r2 = image_radius2(*image.shape[:2])
        return self.curve(_through(image, r2, self.vignetting, self.matrix))

    def to_json(self) -> dict:
        return {"vignetting": self.vignetting.tolist(), "matrix": self.matrix.tolist(),
                "knots_log10": self.knots.tolist(), "response_log10": self.response.tolist()}


_TINY = 1e-6  # radiance floor before a log10 (the matrix can push a dark pixel below zero)


def _log_curve(lx: np.ndarray, knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.empty(lx.shape, float)
    for k in range(3):
        v, x = values[k], lx[..., k]
        lo = (v[1] - v[0]) / (knots[1] - knots[0])
        hi = (v[-1] - v[-2]) / (knots[-1] - knots[-2])
        y = np.interp(x, knots, v)
        y = np.where(x < knots[0], v[0] + lo * (x - knots[0]), y)
        out[..., k] = np.where(x > knots[-1], v[-1] + hi * (x - knots[-1]), y)
    return out


def _through(x: np.ndarray, r2: np.ndarray, vignetting: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    gain = 1.0 + vignetting[0] * r2 + vignetting[1] * r2 ** 2
    return (np.asarray(x, float) * gain[..., None]) @ matrix.T


def image_radius2(height: int, width: int) -> np.ndarray:
    """``(height, width)`` squared distance of each pixel centre from the image centre, over the
    squared half-diagonal (0 at the centre, 1 in a corner)."""
    v, u = np.mgrid[0:height, 0:width]
    return _radius2((u + 0.5) / width, (v + 0.5) / height)


def _radius2(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Squared radius of normalised image coordinates ``x, y`` in [0, 1], corner = 1."""
    return ((x - 0.5) ** 2 + (y - 0.5) ** 2) / 0.5


def _block_index(height: int, width: int, grid: int) -> np.ndarray:
    v, u = np.mgrid[0:height, 0:width]
    return (v * grid // height) * grid + (u * grid // width)


def block_means(image: np.ndarray, grid: int = BLOCK_GRID) -> np.ndarray:
    """``(grid, grid, 3)`` mean linear radiance of ``image (h, w, 3)`` over equal blocks
    (NaN for a block with no pixel, when the image is smaller than the grid)."""
    h, w = image.shape[:2]
    index = _block_index(h, w, grid).ravel()
    n = np.bincount(index, minlength=grid * grid).astype(float)
    sums = np.stack([np.bincount(index, image[..., k].ravel().astype(np.float64), grid * grid)
                     for k in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (sums / n[:, None]).reshape(grid, grid, 3)


def block_radius2(grid: int = BLOCK_GRID) -> np.ndarray:
    """``(grid, grid)`` squared radius (as :func:`image_radius2`) of each block's centre."""
    c = (np.arange(grid) + 0.5) / grid
    return _radius2(c[None, :], c[:, None])


def _unpack(q: np.ndarray, n_knots: int):
    vignetting = q[:2]
    off = q[2:8].reshape(3, 2)
    matrix = np.zeros((3, 3))
    for k in range(3):
        others = [j for j in range(3) if j != k]
        matrix[k, others] = off[k]
        matrix[k, k] = 1.0 - off[k].sum()
    start, log_slopes = q[8:11], q[11:].reshape(3, n_knots - 1)
    return vignetting, matrix, start, log_slopes


def _values(start: np.ndarray, log_slopes: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Log10 response at the knots from its first value and the (log of the) segment slopes."""
    steps = np.exp(log_slopes) * np.diff(knots)
    return np.concatenate([start[:, None], start[:, None] + np.cumsum(steps, axis=1)], axis=1)


def fit_sensor(source_blocks: np.ndarray, target_blocks: np.ndarray,
               n_knots: int = _N_KNOTS) -> Sensor:
    """Fit the sensor step taking renderer A's design images to renderer B's.

    Parameters
    ----------
    source_blocks, target_blocks : np.ndarray
        ``(n_scenes, grid, grid, 3)`` block means of the same design scenes rendered by A and by
        B (:func:`block_means`; linear radiance). NaN blocks are ignored.
    n_knots : int
        Response knots, spread evenly in log10 radiance over the fitted blocks' range (≥ 2).

    Returns
    -------
    Sensor
    """
    if source_blocks.shape != target_blocks.shape or source_blocks.ndim != 4 or source_blocks.shape[-1] != 3:
        raise InputError(None, "blocks", f"the two characterisations' blocks differ in shape "
                                         f"({source_blocks.shape} vs {target_blocks.shape})")
    grid = source_blocks.shape[1]
    r2 = np.broadcast_to(block_radius2(grid), source_blocks.shape[:3])
    a, b = source_blocks.reshape(-1, 3), target_blocks.reshape(-1, 3)
    ok = (np.isfinite(a).all(1) & np.isfinite(b).all(1) & (a.min(1) > DARK_FLOOR)
          & (b.min(1) > DARK_FLOOR))
    if ok.sum() < 50:
        raise InputError(None, "blocks", f"only {int(ok.sum())} blocks bright enough to fit a sensor "
                                         f"step (need 50)")
    a, b, r2 = a[ok], b[ok], r2.reshape(-1)[ok]
    la, lb = np.log10(a), np.log10(b)
    # Knots over A's range; the matrix moves values a little, the end slopes cover the rest.
    knots = np.linspace(np.percentile(la, 0.5), np.percentile(la, 99.9), n_knots)
    # Start: no vignetting, identity matrix, per-channel gain (slope 1) at B's mean level.
    q0 = np.zeros(11 + 3 * (n_knots - 1))
    q0[8:11] = knots[0] + np.median(lb - la, axis=0)

    def residuals(q):
        vignetting, matrix, start, log_slopes = _unpack(q, n_knots)
        y = _through(a, r2, vignetting, matrix)
        fit = _log_curve(np.log10(np.maximum(y, _TINY)), knots, _values(start, log_slopes, knots))
        smooth = _SMOOTH * np.sqrt(len(a)) * np.diff(log_slopes, 2, axis=1).ravel()
        prior = _PRIOR * np.sqrt(len(a)) * q[:8]
        return np.concatenate([(fit - lb).ravel(), smooth, prior])

    sol = least_squares(residuals, q0, loss="soft_l1", f_scale=_ROBUST_SCALE, max_nfev=_MAX_NFEV)
    vignetting, matrix, start, log_slopes = _unpack(sol.x, n_knots)
    return Sensor(vignetting, matrix, knots, _values(start, log_slopes, knots))
