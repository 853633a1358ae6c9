"""Which sensor sites each built pixel averages: the exact linear map of a capture build's
demosaicing and undistortion, for a renderer that draws what the build made.

A built pixel's colour ``c`` is a weighted sum of raw sensor sites: bilinear demosaicing
interpolates each colour from the sites of that colour in a 3 x 3 neighbourhood, and undistortion
resamples bilinearly between four demosaiced pixels, so a built pixel reaches the sites of a
4 x 4 window (superpixels: a 2 x 2 cell per demosaiced pixel, again a 4 x 4 window), each site
holding one colour. A site's raw value is the light falling on its square on the sensor. So::

    built_c(i) = sum_k P_c[i, k] * (mean of L_c over the square of site k),

``P_c`` a sparse matrix per channel (:class:`Footprint`). A renderer that draws each site's mean
over its square (a raw image, one colour per site) and applies ``P`` makes what the build made
from a sensor: :mod:`abs.render.footprint`.

Why exact rather than ``blur_px``'s Gaussian of the same variance (:mod:`.blur`): a Bayer
sensor's red and blue sites sample a quarter of the image, so what bilinear demosaicing makes of
fine detail depends on where the detail falls against the colour filter array (aliasing), which no
blur reproduces; and undistortion's resampling blurs more where its samples fall between pixels
than where they fall on them. Against a build of a simulated sensor (tests/test_footprint.py), the
Gaussian's renderings differ from the built image by structured errors of several per cent of the
signal per pixel; with the Gaussian, the end-to-end benchmark's glass absorption came out about
0.5 per metre off (docs/acquisition.md).

The weights are measured, not derived, like :mod:`.blur`'s variances: raw images holding a one at
every eighth site in each direction (64 phases) go through the build's own
:func:`~abs.acquisition.demosaic.demosaic` and :func:`~abs.acquisition.undistort.remap_bilinear`
as the build runs them (float32), and each built pixel's response to each phase is the weight of
the one site of that phase within its reach (eight sites apart, the reach of four cannot see
two). Every detail of the
pipeline counts: the demosaic's reflected borders, the resampling's 1/32-pixel weights and its
black outside the sensor. A site's square is mapped to the built image through the calibrated
distortion (``cv2.undistortPoints``), linearised over the square (the map's curvature across one
pixel is far below a pixel).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import sparse

from abs.acquisition.camera_file import CameraModel
from abs.acquisition.demosaic import demosaic
from abs.acquisition.undistort import remap_bilinear, sensor_sampling
from abs.io.capture import SensorProcessing

__all__ = ["MAX_SENSOR_PIXELS", "Footprint", "processing_footprint"]

#: Sensors of more pixels are not given a footprint (Camera.from_view falls back to ``blur_px``,
#: with a warning): measuring one takes about 0.8 kB of memory per sensor pixel at its peak and
#: 10 s per megapixel (1280 x 1024: 1.1 GB, 12 s), and the renderer's tables hold about as much.
MAX_SENSOR_PIXELS = 2048 * 2048

# Probe lattice spacing (sensor pixels): more than a built pixel's reach (4 sites), even so that
# each probe keeps one CFA colour.
_SPACING = 8


@dataclass(frozen=True, eq=False)
class Footprint:
    """The sensor sites each built pixel averages (module docstring).

    Attributes
    ----------
    width, height : int
        The built image's size, pixels.
    site_center : np.ndarray
        ``(S, 2)`` float64, each sensor site's centre in built-image pixels (OpenCV convention:
        pixel centres at integers); ``S`` = sensor width x height, row-major.
    site_jacobian : np.ndarray
        ``(S, 2, 2)`` float64, d(built position) / d(sensor position) at each site: its square
        ``[-1/2, 1/2]^2`` on the sensor maps to ``center + J @ offset``.
    weights : tuple of 3 scipy.sparse.csr_matrix
        ``P_R, P_G, P_B``, each ``(height * width, S)``: built pixel (row-major) from sites.
    processing : SensorProcessing
        What the build did (the sensor's camera, demosaicing, CFA pattern).
    K_new : np.ndarray
        (3, 3) the built image's pinhole camera, pixels.
    """

    width: int
    height: int
    site_center: np.ndarray
    site_jacobian: np.ndarray
    weights: tuple
    processing: SensorProcessing
    K_new: np.ndarray

    def site_at(self, xy: np.ndarray, jitter: np.ndarray | None = None) -> np.ndarray:
        """The sensor site (index into ``site_center``) whose square holds each built-image point
        ``xy`` (``(N, 2)``, pixels), ``-1`` off the sensor: the point projected through the
        calibrated distortion (``cv2.projectPoints``), moved by ``jitter`` (``(N, 2)`` sensor
        pixels, optional: a draw of the lens's point-spread function) and rounded to the nearest
        site."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        rays = np.linalg.solve(self.K_new, np.column_stack([xy, np.ones(len(xy))]).T).T
        sensor, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                      np.asarray(self.processing.K, np.float64),
                                      np.asarray(self.processing.distortion, np.float64))
        sensor = sensor.reshape(-1, 2) + (0.0 if jitter is None else jitter)
        sx, sy = np.round(sensor).astype(np.int64).T
        w, h = self.processing.width, self.processing.height
        on = (sx >= 0) & (sx < w) & (sy >= 0) & (sy < h)
        return np.where(on, sy * w + sx, -1)

    def expected(self, site_values: np.ndarray) -> np.ndarray:
        """The built image ``(H, W, 3)`` of sites whose squares' mean light is ``site_values``
        (``(S, 3)``; a site counts only in its own colour's channel)."""
        values = np.asarray(site_values, np.float64)
        return np.stack([P @ values[:, c] for c, P in enumerate(self.weights)],
                        -1).reshape(self.height, self.width, 3)


def _sensor_camera(processing: SensorProcessing) -> CameraModel:
    return CameraModel(processing.width, processing.height, np.asarray(processing.K, np.float64),
                       np.asarray(processing.distortion, np.float64), np.eye(3), np.zeros(3))


def _pipeline(processing: SensorProcessing, K_new: np.ndarray):
    """The build's processing of a raw ``(H_s, W_s)`` mosaic as a function, and where each built
    pixel samples the sensor (full-resolution sensor pixels)."""
    camera = _sensor_camera(processing)
    method = processing.demosaic
    map_x, map_y, source_x, source_y = sensor_sampling(camera, K_new, method == "superpixel")

    def through(raw: np.ndarray) -> np.ndarray:
        # In float32 as the build computes (abs.acquisition.build): OpenCV resamples float32
        # images with weights in 1/32 pixel steps, float64 ones with exact weights.
        rgb = (np.repeat(raw[..., None], 3, axis=-1).astype(np.float32) if method is None
               else demosaic(raw, processing.cfa_pattern, method))
        return remap_bilinear(rgb, map_x, map_y).astype(np.float64)

    return through, source_x, source_y, camera


def _sites_in_built_image(camera: CameraModel, K_new: np.ndarray):
    """Every sensor site's centre in the built image and the Jacobian of sensor -> built there."""
    v, u = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    h = 0.5
    points = np.stack([np.stack([u, v], -1), np.stack([u + h, v], -1), np.stack([u - h, v], -1),
                       np.stack([u, v + h], -1), np.stack([u, v - h], -1)]).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    normal = cv2.undistortPoints(points, camera.K, camera.distortion,
                                 criteria=criteria).reshape(5, -1, 2)
    built = normal @ K_new[:2, :2].T + K_new[:2, 2]
    center = built[0]
    jacobian = np.stack([(built[1] - built[2]) / (2 * h), (built[3] - built[4]) / (2 * h)], -1)
    return center, jacobian


def processing_footprint(processing: SensorProcessing, K_new: np.ndarray, width: int,
                         height: int) -> Footprint:
    """The sites each pixel of a built image averages (module docstring).

    Parameters
    ----------
    processing : SensorProcessing
        What the build did (``cameras.json``'s ``processing`` of the view).
    K_new : ndarray, shape (3, 3)
        The built image's pinhole camera (the view's ``K``), pixels.
    width, height : int
        The built image's size (the sensor's, or half of it for superpixels).

    Returns
    -------
    Footprint

    Raises
    ------
    ValueError
        When the sizes do not fit the processing (a superpixel image is half the sensor's).
    """
    K_new = np.asarray(K_new, np.float64)
    factor = 2 if processing.demosaic == "superpixel" else 1
    if (width * factor, height * factor) != (processing.width, processing.height):
        raise ValueError(f"a {width}x{height} image cannot come from the {processing.width}x"
                         f"{processing.height} sensor by demosaic {processing.demosaic}")
    through, source_x, source_y, camera = _pipeline(processing, K_new)
    n_sites = processing.width * processing.height
    pixels = np.arange(width * height).reshape(height, width)
    rows, cols, values = [], [], []
    for oy in range(_SPACING):
        for ox in range(_SPACING):
            raw = np.zeros((processing.height, processing.width))
            raw[oy::_SPACING, ox::_SPACING] = 1.0
            out = through(raw)
            reached = np.any(out != 0.0, axis=-1)
            # The one site of this phase within the pixel's reach: the lattice point nearest to
            # where the pixel samples the sensor.
            sx = ox + _SPACING * np.round((source_x - ox) / _SPACING)
            sy = oy + _SPACING * np.round((source_y - oy) / _SPACING)
            inside = (sx >= 0) & (sx < processing.width) & (sy >= 0) & (sy < processing.height)
            if np.any(reached & ~inside):
                raise AssertionError("a built pixel responds to a site outside the sensor")
            rows.append(pixels[reached].astype(np.int32))
            cols.append((sy * processing.width + sx)[reached].astype(np.int32))
            values.append(out[reached].astype(np.float32))  # the build's weights are float32
    rows, cols, values = np.concatenate(rows), np.concatenate(cols), np.concatenate(values)
    shape = (width * height, n_sites)
    weights = []
    for c in range(3):
        used = values[:, c] != 0.0
        weights.append(sparse.csr_matrix((values[used, c], (rows[used], cols[used])), shape=shape))
    weights = tuple(weights)
    center, jacobian = _sites_in_built_image(camera, K_new)
    return Footprint(width, height, center, jacobian, weights, processing, K_new)
