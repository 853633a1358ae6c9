"""Rendering a built photograph's pixels as its build made them: sensor sites, then the build's
weights (:mod:`abs.acquisition.footprint`).

A camera with a footprint renders the *sensor*: every sensor site its pixels use gets its own
samples, drawn uniformly in the site's square (mapped into the camera's image through the
calibrated distortion), and its value is their mean. The camera's pixels are then the build's
weighted sums of those site values, per channel (``P_c``, a site counting only in its own colour's
channel). This is the photograph's own processing applied to a rendered raw image, so the
Monte-Carlo noise of a site is shared, like the sensor's noise, by every pixel that uses it: a
bilinear build at ``spp`` samples per pixel renders about ``spp`` per site, and a pixel's red,
interpolated from up to four red sites, is no noisier than a tent-filtered pixel's. (Drawing each
pixel's own samples from its sites instead would spend two thirds of them on sites of other
colours.)

Everything here is linear in the sites' values, so derivatives pass through unchanged: the
forward-mode tangent is filmed like the radiance, path replay's adjoint is ``P^T`` of the image's
adjoint, and a path-length recording bins each sample's light into every pixel that uses its site,
with that pixel's weight. Downsampled cameras (``block > 1``) average the full-resolution rows of
``P`` over each block. The tables are built once per footprint and block (NumPy) and copied to
Dr.Jit once per variant.
"""

from __future__ import annotations

from dataclasses import dataclass
from weakref import WeakKeyDictionary

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy import sparse

from abs.acquisition.footprint import Footprint
from abs.render.jit import from_numpy, opaque

__all__ = ["FootprintFilm", "footprint_film"]


@dataclass(eq=False)
class _Tables:
    """NumPy tables of one footprint at one block size."""

    sites: np.ndarray          # (M,) the sensor sites rendered (indices into the footprint's)
    pixels: int                # the camera's pixels
    forward: list              # per channel: (idx (pixels, N_c) into sites, weight (pixels, N_c))
    transpose: list            # per channel: (pixel (M, T_c), weight (M, T_c))


def _padded_rows(matrix: sparse.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """A CSR matrix's rows as ``(columns, values)`` padded with (0, 0.0) to the longest row."""
    counts = np.diff(matrix.indptr)
    n = max(int(counts.max()) if counts.size else 0, 1)
    cols = np.zeros((matrix.shape[0], n), np.int64)
    vals = np.zeros((matrix.shape[0], n), np.float64)
    slot = np.arange(matrix.nnz) - np.repeat(matrix.indptr[:-1], counts)
    row = np.repeat(np.arange(matrix.shape[0]), counts)
    cols[row, slot] = matrix.indices
    vals[row, slot] = matrix.data
    return cols, vals


def _tables(footprint: Footprint, block: int, width: int, height: int) -> _Tables:
    weights = footprint.weights
    if block > 1:
        # Camera pixel (j, i) averages full-resolution pixels of rows j*b.., columns i*b..
        fine = np.arange(footprint.width * footprint.height).reshape(footprint.height, footprint.width)
        fine = fine[:height * block, :width * block]
        coarse = np.repeat(np.repeat(np.arange(width * height).reshape(height, width), block, 0),
                           block, 1)
        average = sparse.csr_matrix((np.full(fine.size, 1.0 / block ** 2),
                                     (coarse.ravel(), fine.ravel())),
                                    shape=(width * height, footprint.width * footprint.height))
        weights = tuple((average @ P).tocsr() for P in weights)
    elif (width, height) != (footprint.width, footprint.height):
        weights = tuple(_crop(P, footprint, width, height) for P in weights)
    used = np.unique(np.concatenate([P.indices for P in weights]))
    local = [P[:, used].tocsr() for P in weights]
    forward = [_padded_rows(P) for P in local]
    transpose = [_padded_rows(P.T.tocsr()) for P in local]
    return _Tables(used, width * height, forward, transpose)


def _crop(P, footprint: Footprint, width: int, height: int):
    """The rows of the top-left ``width`` x ``height`` pixels (a camera smaller than the image)."""
    rows = np.arange(footprint.width * footprint.height).reshape(footprint.height,
                                                                 footprint.width)[:height, :width]
    return P[rows.ravel()].tocsr()


class FootprintFilm:
    """A camera's footprint as Dr.Jit tables: where its site samples go and how sites make pixels.

    Use :func:`footprint_film` (cached per footprint, block and variant).
    """

    def __init__(self, footprint: Footprint, block: int, width: int, height: int):
        t = _tables(footprint, block, width, height)
        self.block = block
        self.sites = len(t.sites)
        self.pixels = t.pixels
        c, j = footprint.site_center[t.sites], footprint.site_jacobian[t.sites]
        if block > 1:
            # Full-resolution positions -> the downsampled camera's (abs.model.downsampling).
            shift = (block - 1) / 2.0
            c, j = (c - shift) / block, j / block
        self.cx, self.cy = from_numpy(mi.Float, c[:, 0]), from_numpy(mi.Float, c[:, 1])
        self.j = [[from_numpy(mi.Float, j[:, r, k]) for k in range(2)] for r in range(2)]
        self.forward = [(from_numpy(mi.UInt32, idx, np.uint32), from_numpy(mi.Float, w), idx.shape[1])
                        for idx, w in t.forward]
        self.transpose = [(from_numpy(mi.UInt32, pix, np.uint32), from_numpy(mi.Float, w), pix.shape[1])
                          for pix, w in t.transpose]

    def site_spp(self, spp: int) -> int:
        """Samples per site for ``spp`` samples per pixel: the same samples in all."""
        return max(1, int(round(spp * self.pixels / self.sites)))

    def positions(self, sampler: mi.Sampler, lane: mi.UInt32, spp: int):
        """Each lane's site (``site_spp`` consecutive lanes per site) and a uniform point in its
        square, in the camera's pixel coordinates."""
        site = lane // opaque(mi.UInt32, self.site_spp(spp))
        offset = sampler.next_2d() - 0.5
        x = (dr.gather(mi.Float, self.cx, site) + dr.gather(mi.Float, self.j[0][0], site) * offset.x
             + dr.gather(mi.Float, self.j[0][1], site) * offset.y)
        y = (dr.gather(mi.Float, self.cy, site) + dr.gather(mi.Float, self.j[1][0], site) * offset.x
             + dr.gather(mi.Float, self.j[1][1], site) * offset.y)
        return site, x, y

    def film(self, radiance: mi.Color3f, spp: int, width: int, height: int) -> mi.TensorXf:
        """The camera's image from the lanes' radiance: sites' means, then the build's weights."""
        per = self.site_spp(spp)
        inv = opaque(mi.Float, 1.0 / per)
        flat = dr.zeros(mi.Float, self.pixels * 3)
        pixel = dr.arange(mi.UInt32, self.pixels)
        for c, value in enumerate((radiance.x, radiance.y, radiance.z)):
            site_mean = dr.block_sum(value, per) * inv
            idx, w, n = self.forward[c]
            total = mi.Float(0.0)
            for k in range(n):
                entry = pixel * opaque(mi.UInt32, n) + k
                total += dr.gather(mi.Float, w, entry) * dr.gather(mi.Float, site_mean,
                                                                     dr.gather(mi.UInt32, idx, entry))
            dr.scatter(flat, total, pixel * 3 + c)
        return mi.TensorXf(flat, (height, width, 3))

    def adjoint(self, weight: mi.Float, site: mi.UInt32, spp: int) -> mi.Color3f:
        """Each lane's share of an image adjoint ``weight`` (flat, pixel-major RGB): ``P^T``."""
        inv = opaque(mi.Float, 1.0 / self.site_spp(spp))
        out = []
        for c in range(3):
            pix, w, n = self.transpose[c]
            total = mi.Float(0.0)
            for k in range(n):
                entry = site * opaque(mi.UInt32, n) + k
                total += dr.gather(mi.Float, w, entry) * dr.gather(
                    mi.Float, weight, dr.gather(mi.UInt32, pix, entry) * 3 + c)
            out.append(total * inv)
        return mi.Color3f(*out)

    def splats(self, site: mi.UInt32, spp: int):
        """For a recording: per channel and entry, the pixels each lane's light lands in and the
        weights relative to ``1 / spp`` (what :meth:`PathTracer.record` divides by)."""
        scale = opaque(mi.Float, spp / self.site_spp(spp))
        for c in range(3):
            pix, w, n = self.transpose[c]
            for k in range(n):
                entry = site * opaque(mi.UInt32, n) + k
                yield c, dr.gather(mi.UInt32, pix, entry), dr.gather(mi.Float, w, entry) * scale


_FILMS: WeakKeyDictionary = WeakKeyDictionary()


def footprint_film(footprint: Footprint, block: int, width: int, height: int) -> FootprintFilm:
    """The Dr.Jit tables of ``footprint`` for a camera of ``block`` and size (cached)."""
    key = (block, width, height, mi.variant())
    films = _FILMS.setdefault(footprint, {})
    if key not in films:
        films[key] = FootprintFilm(footprint, block, width, height)
    return films[key]
