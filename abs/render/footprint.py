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

A lens blur (``lens_blur_px`` of the capture's processing, a Gaussian point-spread function on the
sensor) moves each sample by a draw of it: a site then sees the light of its square blurred.

Everything here is linear in the sites' values, so derivatives pass through unchanged: the
forward-mode tangent is filmed like the radiance, path replay's adjoint is ``P^T`` of the image's
adjoint, a path-length recording bins each sample's light into every pixel that uses its site,
with that pixel's weight, and edge sampling puts a moving silhouette's boundary term into the site
whose square holds each edge point (:meth:`FootprintFilm.sites_at`). Downsampled cameras
(``block > 1``) average the full-resolution rows of ``P`` over each block; a sample boost gives its
factor to every site a pixel of its rectangle uses. The tables are built once per footprint,
block, size and boost (NumPy) and copied to Dr.Jit once per variant.
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
    weights: list              # per channel: P_c, (pixels, M) CSR over the rendered sites
    forward: list              # per channel: (idx (pixels, N_c) into sites, weight (pixels, N_c))
    transpose: list            # per channel: (pixel (M, T_c), weight (M, T_c))


def _padded_rows(matrix: sparse.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """A CSR matrix's rows as ``(columns, values)`` padded with (0, 0.0) to the longest row."""
    counts = np.diff(matrix.indptr)
    n = max(int(counts.max()) if counts.size else 0, 1)
    cols = np.zeros((matrix.shape[0], n), np.int32)
    vals = np.zeros((matrix.shape[0], n), np.float32)
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
    local = [P[:, used].astype(np.float64).tocsr() for P in weights]
    forward = [_padded_rows(P) for P in local]
    transpose = [_padded_rows(P.T.tocsr()) for P in local]
    return _Tables(used, width * height, local, forward, transpose)


def _crop(P, footprint: Footprint, width: int, height: int):
    """The rows of the top-left ``width`` x ``height`` pixels (a camera smaller than the image)."""
    rows = np.arange(footprint.width * footprint.height).reshape(footprint.height,
                                                                 footprint.width)[:height, :width]
    return P[rows.ravel()].tocsr()


class FootprintFilm:
    """A camera's footprint as Dr.Jit tables: where its site samples go and how sites make pixels.

    Use :func:`footprint_film` (cached per footprint, block and variant).
    """

    def __init__(self, footprint: Footprint, block: int, width: int, height: int, boost=None):
        t = _tables(footprint, block, width, height)
        self.block = block
        self.sites = len(t.sites)
        self.pixels = t.pixels
        c, j = footprint.site_center[t.sites], footprint.site_jacobian[t.sites]
        if block > 1:
            # Full-resolution positions -> the downsampled camera's (abs.model.downsampling).
            shift = (block - 1) / 2.0
            c, j = (c - shift) / block, j / block
        self._footprint = footprint
        self.lens_blur = float(footprint.processing.lens_blur_px)
        self._weights = t.weights
        self._size = (height, width)
        self._local = np.full(footprint.site_center.shape[0], -1, np.int64)
        self._local[t.sites] = np.arange(self.sites)
        self._area = np.abs(np.linalg.det(j))  # a site's square in the camera's pixels^2
        self.cx, self.cy = from_numpy(mi.Float, c[:, 0]), from_numpy(mi.Float, c[:, 1])
        self.j = [[from_numpy(mi.Float, j[:, r, k]) for k in range(2)] for r in range(2)]
        self.forward = [(from_numpy(mi.UInt32, idx, np.uint32), from_numpy(mi.Float, w), idx.shape[1])
                        for idx, w in t.forward]
        self.transpose = [(from_numpy(mi.UInt32, pix, np.uint32), from_numpy(mi.Float, w), pix.shape[1])
                          for pix, w in t.transpose]
        # A sample boost (abs.render.camera.SampleBoost) multiplies the samples of every site
        # that a pixel of its rectangle uses; those sites' extra lanes follow all ordinary ones.
        self.factor = 1 if boost is None else int(boost.factor)
        boosted = np.zeros(0, np.int64)
        if boost is not None:
            rows = np.arange(width * height).reshape(height, width)[boost.y0:boost.y1, boost.x0:boost.x1]
            boosted = np.unique(np.concatenate([idx[rows.ravel()][w[rows.ravel()] != 0]
                                                for idx, w in t.forward]))
        self.boosted = len(boosted)
        factor = np.ones(self.sites)
        factor[boosted] = self.factor
        self.boosted_sites = from_numpy(mi.UInt32, boosted if len(boosted) else np.zeros(1), np.uint32)
        self.site_factor = from_numpy(mi.Float, factor)

    def apply_numpy(self, site_values: np.ndarray) -> np.ndarray:
        """The camera's ``(height, width, 3)`` image of per-channel site values ``(sites, 3)``
        (NumPy, float64): the build's weights, as :meth:`image` applies them in Dr.Jit."""
        values = np.asarray(site_values, np.float64)
        return np.stack([P @ values[:, c] for c, P in enumerate(self._weights)],
                        -1).reshape(*self._size, 3)

    def correlate(self, X: np.ndarray) -> np.ndarray:
        """``K X`` for ``X`` of shape ``(pixels, 3, n)`` (the camera's pixels row-major, per
        channel): ``K = P P^T / k``, the correlation between pixels that independent noise of one
        level on every site takes through the build's weights, ``k`` making its mean diagonal 1
        (:meth:`white_noise_std` squared)."""
        X = np.asarray(X, np.float64)
        k = self.white_noise_std() ** 2
        return np.stack([P @ (P.T @ X[:, c]) / k for c, P in enumerate(self._weights)], axis=1)

    def white_noise_std(self) -> float:
        """The per-pixel standard deviation (RMS over pixels and channels) that independent unit
        noise on every site leaves in the camera's image."""
        return float(np.sqrt(np.mean([P.multiply(P).sum() / P.shape[0] for P in self._weights])))

    def site_spp(self, spp: int) -> int:
        """Samples per (unboosted) site for ``spp`` samples per pixel: the same samples in all."""
        return max(1, int(round(spp * self.pixels / self.sites)))

    def lanes(self, spp: int) -> int:
        """Lanes of a render at ``spp``: every site's, then the boosted sites' extra ones."""
        per = self.site_spp(spp)
        return self.sites * per + self.boosted * per * (self.factor - 1)

    def _inverse_count(self, site: mi.UInt32, spp: int) -> mi.Float:
        """``1 /`` the number of samples of each lane's site."""
        return opaque(mi.Float, 1.0 / self.site_spp(spp)) / dr.gather(mi.Float, self.site_factor, site)

    def positions(self, sampler: mi.Sampler, lane: mi.UInt32, spp: int):
        """Each lane's site (``site_spp`` consecutive lanes per site, then ``site_spp *
        (factor - 1)`` per boosted site) and a uniform point in its square, in the camera's pixel
        coordinates."""
        per = self.site_spp(spp)
        site = lane // opaque(mi.UInt32, per)
        if self.boosted:
            base = opaque(mi.UInt32, self.sites * per)
            extra = lane >= base
            j = dr.select(extra, lane - base, 0) // opaque(mi.UInt32, per * (self.factor - 1))
            site = dr.select(extra, dr.gather(mi.UInt32, self.boosted_sites, j), site)
        offset = sampler.next_2d() - 0.5
        if self.lens_blur > 0:
            # The lens's point-spread function: light reaching the square from around it.
            offset = offset + mi.warp.square_to_std_normal(sampler.next_2d()) * opaque(
                mi.Float, self.lens_blur)
        x = (dr.gather(mi.Float, self.cx, site) + dr.gather(mi.Float, self.j[0][0], site) * offset.x
             + dr.gather(mi.Float, self.j[0][1], site) * offset.y)
        y = (dr.gather(mi.Float, self.cy, site) + dr.gather(mi.Float, self.j[1][0], site) * offset.x
             + dr.gather(mi.Float, self.j[1][1], site) * offset.y)
        return site, x, y

    def _site_means(self, value: mi.Float, spp: int) -> mi.Float:
        """Each site's mean of its lanes' ``value`` (block sums: the same samples give the same
        image, bit for bit)."""
        per = self.site_spp(spp)
        if not self.boosted:
            return dr.block_sum(value, per) * opaque(mi.Float, 1.0 / per)
        ordinary = dr.block_sum(dr.gather(mi.Float, value, dr.arange(mi.UInt32, self.sites * per)), per)
        more = per * (self.factor - 1)
        lanes = opaque(mi.UInt32, self.sites * per) + dr.arange(mi.UInt32, self.boosted * more)
        extra = dr.zeros(mi.Float, self.sites)
        dr.scatter(extra, dr.block_sum(dr.gather(mi.Float, value, lanes), more), self.boosted_sites)
        count = opaque(mi.Float, per) * self.site_factor
        return (ordinary + extra) / count

    def film(self, radiance: mi.Color3f, spp: int, width: int, height: int) -> mi.TensorXf:
        """The camera's image from the lanes' radiance: sites' means, then the build's weights."""
        return self.image([self._site_means(value, spp)
                           for value in (radiance.x, radiance.y, radiance.z)], width, height)

    def sites_at(self, xy: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """For points ``xy`` (``(N, 2)``, the camera's pixels): the rendered site whose square
        holds each (``-1`` for none; with a lens blur, the square holding the point moved by a
        draw of the point-spread function from ``rng``: the site's share of the point's light,
        on average) and ``1 /`` that square's area in the camera's pixels^2 (a site's value is
        the mean over its square)."""
        xy = np.asarray(xy, np.float64)
        if self.block > 1:
            xy = xy * self.block + (self.block - 1) / 2.0  # the full-resolution image's pixels
        jitter = rng.normal(0.0, self.lens_blur, xy.shape) if self.lens_blur > 0 else None
        site = self._footprint.site_at(xy, jitter)
        local = np.where(site >= 0, self._local[np.maximum(site, 0)], -1)
        inverse_area = np.where(local >= 0, 1.0 / self._area[np.maximum(local, 0)], 0.0)
        return local, inverse_area

    def image(self, site_values, width: int, height: int) -> mi.TensorXf:
        """The camera's image from per-channel site values (three ``mi.Float`` of ``sites``)."""
        flat = dr.zeros(mi.Float, self.pixels * 3)
        pixel = dr.arange(mi.UInt32, self.pixels)
        for c, site_mean in enumerate(site_values):
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
        inv = self._inverse_count(site, spp)
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
        scale = self._inverse_count(site, spp) * opaque(mi.Float, spp)
        for c in range(3):
            pix, w, n = self.transpose[c]
            for k in range(n):
                entry = site * opaque(mi.UInt32, n) + k
                yield c, dr.gather(mi.UInt32, pix, entry), dr.gather(mi.Float, w, entry) * scale


_FILMS: WeakKeyDictionary = WeakKeyDictionary()


def footprint_film(footprint: Footprint, block: int, width: int, height: int,
                   boost=None) -> FootprintFilm:
    """The Dr.Jit tables of ``footprint`` for a camera of ``block``, size and sample ``boost``
    (a :class:`~abs.render.camera.SampleBoost` or ``None``), cached."""
    key = (block, width, height, boost, mi.variant())
    films = _FILMS.setdefault(footprint, {})
    if key not in films:
        films[key] = FootprintFilm(footprint, block, width, height, boost)
    return films[key]
