"""Camera rays in the OpenCV pinhole convention (docs/conventions.md), generated in Dr.Jit.

abs generates primary rays itself rather than through Mitsuba's ``perspective`` sensor: the
calibration (``K`` with fx != fy, skew, any principal point) maps to rays exactly, and the same
matrices project silhouette edges for visibility gradients (:mod:`abs.render.edges`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.acquisition.footprint import MAX_SENSOR_PIXELS, Footprint, processing_footprint
from abs.render.footprint import footprint_film
from abs.render.jit import opaque

__all__ = ["Camera", "SampleBoost"]


@dataclass(frozen=True)
class SampleBoost:
    """More samples in one rectangle of pixels: ``[y0:y1, x0:x1]`` takes ``factor`` times the
    render's samples per pixel.

    Where glass is seen, its refractions are the noisiest part of an image and carry what an IOR
    is measured by; spending samples there shrinks the Monte-Carlo error of a glass fit's
    objective and Jacobian for a fraction of the cost of more samples everywhere. The estimate
    stays unbiased: every pixel averages its own samples.
    """

    x0: int
    y0: int
    x1: int
    y1: int
    factor: int

    def __post_init__(self):
        if not (0 <= self.x0 < self.x1 and 0 <= self.y0 < self.y1) or self.factor < 2:
            raise ValueError(f"a sample boost needs a non-empty rectangle and factor >= 2, not {self}")

    @property
    def pixels(self) -> int:
        return (self.x1 - self.x0) * (self.y1 - self.y0)


@dataclass(frozen=True)
class Camera:
    """A calibrated pinhole camera.

    Parameters
    ----------
    K : ndarray, shape (3, 3)
        Intrinsics in pixels.
    R : ndarray, shape (3, 3)
        World-to-camera rotation, ``x_cam = R @ X + t``.
    t : ndarray, shape (3,)
        World-to-camera translation in metres.
    width, height : int
        Image size in pixels.
    block : int
        Each pixel is the average of ``block`` x ``block`` pixels of a finer image (a camera
        downsampled for comparison with box-averaged photographs); 1 for an ordinary camera.
    blur_px : tuple of 3 float
        Standard deviation of a Gaussian point-spread function per R, G, B, in pixels of the
        full-resolution photographs (``block = 1``): the blur that the photographs' processing
        added beyond a pixel's own footprint (demosaicing, resampling; capture files'
        ``blur_px``, :mod:`abs.io.capture`). Applied by the sensor
        (:meth:`abs.render.sensor.Sensor.apply`); zeros for none.
    boost : SampleBoost or None
        Pixels that take more samples than the others (inside the image).
    footprint : Footprint or None
        The sensor sites each full-resolution pixel averages, when the photographs were built
        from a sensor whose processing the capture describes (:mod:`abs.acquisition.footprint`):
        the sites are rendered from samples in their squares and the pixels made from them with
        the build's weights (:mod:`abs.render.footprint`), instead of the tent filter; ``blur_px``
        is then zero and a ``boost`` boosts the sites its pixels use.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    block: int = 1
    blur_px: tuple[float, float, float] = (0.0, 0.0, 0.0)
    boost: SampleBoost | None = None
    footprint: Footprint | None = field(default=None, compare=False)

    def __post_init__(self):
        b = self.boost
        if b is not None and (b.x1 > self.width or b.y1 > self.height):
            raise ValueError(f"sample boost {b} reaches outside the {self.width}x{self.height} image")
        fp = self.footprint
        if fp is not None:
            if (fp.width < self.width * self.block or fp.height < self.height * self.block):
                raise ValueError(f"a footprint of {fp.width}x{fp.height} pixels cannot serve a "
                                 f"{self.width}x{self.height} camera of blocks of {self.block}")
            if any(self.blur_px):
                raise ValueError("a camera with a footprint draws the processing exactly: its "
                                 f"blur_px must be zero, not {self.blur_px}")

    def samples(self, spp: int) -> int:
        """Camera samples (lanes) of a render at ``spp``: the boosted pixels' extra ones too, or
        the sensor sites' under a footprint."""
        if self.footprint is not None:
            return self.film().lanes(spp)
        extra = 0 if self.boost is None else self.boost.pixels * (self.boost.factor - 1)
        return (self.width * self.height + extra) * spp

    def film(self):
        """The :class:`~abs.render.footprint.FootprintFilm` of a camera with a footprint."""
        return footprint_film(self.footprint, self.block, self.width, self.height, self.boost)

    @classmethod
    def from_view(cls, view) -> "Camera":
        """From a :class:`abs.io.capture.View`: its photograph's processing drawn exactly when
        the capture describes it (``view.processing``: a footprint), else blurred by its
        ``blur_px``."""
        K = np.asarray(view.K, float)
        processing = view.processing
        if processing is not None and processing.width * processing.height > MAX_SENSOR_PIXELS:
            warnings.warn(f"view {view.name}: the {processing.width}x{processing.height} sensor "
                          f"is too large to render its sites (more than {MAX_SENSOR_PIXELS} "
                          "pixels): its processing is approximated by blur_px's Gaussian",
                          stacklevel=2)
            processing = None
        if processing is not None:
            footprint = _footprint(processing.key(), processing, tuple(K.ravel()),
                                   int(view.width), int(view.height))
            return cls(K, np.asarray(view.R, float), np.asarray(view.t, float), int(view.width),
                       int(view.height), footprint=footprint)
        return cls(K, np.asarray(view.R, float), np.asarray(view.t, float),
                   int(view.width), int(view.height), 1, tuple(float(s) for s in view.blur_px))

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates (metres)."""
        return -self.R.T @ self.t

    def _mats(self):
        # Opaque: a new camera must not bake new literals into (and recompile) the kernels.
        kinv = np.linalg.inv(self.K)
        return tuple(opaque(mi.Matrix3f, m) for m in (kinv, self.R.T, self.K, self.R))

    def rays(self, u: mi.Float, v: mi.Float) -> tuple[mi.Point3f, mi.Vector3f]:
        """World-space unit rays through continuous pixel positions ``(u, v)``."""
        kinv, rt, _, _ = self._mats()
        d_cam = kinv @ mi.Vector3f(u, v, 1.0)
        d = dr.normalize(rt @ d_cam)
        return opaque(mi.Point3f, *self.center.tolist()), d

    def project(self, p: mi.Point3f) -> tuple[mi.Float, mi.Float]:
        """Pixel position ``(u, v)`` of world points ``p``, differentiable in ``p``."""
        _, _, k, r = self._mats()
        q = k @ (r @ p + opaque(mi.Vector3f, *self.t.tolist()))
        return q.x / q.z, q.y / q.z


_FOOTPRINTS: dict[tuple, Footprint] = {}
_FOOTPRINTS_KEPT = 32


def _footprint(key: tuple, processing, K: tuple, width: int, height: int) -> Footprint:
    """One footprint per distinct processing and camera (``key``, ``K`` and size): views of one
    camera share it, and a fit's repeated ``from_view`` does not measure it again."""
    full_key = (key, K, width, height)
    if full_key not in _FOOTPRINTS:
        if len(_FOOTPRINTS) >= _FOOTPRINTS_KEPT:
            _FOOTPRINTS.pop(next(iter(_FOOTPRINTS)))
        _FOOTPRINTS[full_key] = processing_footprint(processing, np.reshape(K, (3, 3)), width,
                                                     height)
    return _FOOTPRINTS[full_key]
