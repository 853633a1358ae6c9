"""The blur that a capture build's processing adds: demosaicing and undistortion, as one number
per colour channel.

A fit compares each photograph with a rendering whose pixels see the scene through the renderer's
own footprint (a tent filter of radius one pixel, :data:`PIXEL_FOOTPRINT_VARIANCE_PX2` per axis),
which also stands for the sensor pixel's. A built photograph has been through more: bilinear
demosaicing interpolates two of every three colour values from neighbouring sites, and
undistortion resamples the image bilinearly. Both are linear filters with non-negative weights
that sum to one, so each pixel of the built image is a weighted mean of sensor sites, and the
**variance of the sites' positions under those weights** is the blur they add (to second order:
what sets the loss of contrast of smooth detail; a Gaussian of that variance has the same effect
on low spatial frequencies). The renderer cannot draw that blur unless it is told; fitted
parameters then make up for the lost contrast (glass absorption came out several per metre too
high in the end-to-end benchmark, docs/acquisition.md).

The variances are measured, not derived: images of the sensor sites' coordinates ``x``, ``x^2``
(and ``y``, ``y^2``) are pushed through the build's own demosaicing and undistortion's bilinear
resampling, in float64, and ``E[x^2] - E[x]^2`` is read off per pixel and channel. So every
detail of the pipeline counts (the CFA pattern's phase, which sites a superpixel averages, the
undistortion's zoom and its fractional sample positions), and a change to the pipeline changes
the blur with it. Photographs of more than 2 megapixels are measured on 3 x 3 tiles of 256 x 256
sensor pixels spread over the frame (the built pixels that sample them), not on the whole frame,
whose float64 coordinate images would take gigabytes for a 24-megapixel sensor.

In the capture's pixels (``s`` of them per sensor pixel: ``f_new / f``, about 1 for bilinear, 1/2
for superpixels) the blur beyond the renderer's footprint is::

    sigma_c^2 = s^2 var_c + F (s^2 - 1),     F = 1/6 px^2,

the second term because a sensor pixel's footprint is ``s`` capture pixels wide while the
renderer draws one capture pixel's; negative values (superpixels sample sites smaller than the
pixel) are clipped to 0. Averaged over the image's interior (pixels whose samples stay two
pixels inside the sensor), the same for every pixel: the blur varies little across the frame
(the demosaic's per-phase kernels average out over a few pixels).
"""

from __future__ import annotations

import numpy as np

from abs.acquisition.camera_file import CameraModel
from abs.acquisition.demosaic import demosaic
from abs.acquisition.undistort import remap_bilinear, sensor_sampling, superpixel_camera

__all__ = ["PIXEL_FOOTPRINT_VARIANCE_PX2", "processing_blur"]

#: Variance per axis (pixels^2) of the footprint the renderer gives a pixel: its tent filter of
#: radius 1 pixel (abs.render.integrator; tests/test_acquisition_blur.py checks the two agree).
PIXEL_FOOTPRINT_VARIANCE_PX2 = 1.0 / 6.0

# Built pixels whose bilinear samples come from this close to the edge of the sensor (or of a
# tile) are left out: there the demosaic's reflected border and the resampling's constant border
# break "weights sum to one".
_MARGIN_PX = 2.0
# Above this many sensor pixels, tiles of this size (even: the CFA's phase is kept) are measured.
_WHOLE_FRAME_PX = 2_000_000
_TILE_PX = 256
# cv2.remap takes maps of fewer than 32767 columns: scattered samples go in rows of this length.
_ROW = 1024


def _tiles(height: int, width: int, whole_frame_px: int) -> list[tuple[int, int, int, int]]:
    """The sensor regions measured, ``(y0, y1, x0, x1)``: the whole frame, or 3 x 3 tiles of
    ``_TILE_PX`` spread evenly over it, their corners even (the CFA's phase kept)."""
    if height * width <= whole_frame_px or min(height, width) < _TILE_PX:
        return [(0, height, 0, width)]

    def starts(n):
        return [2 * (int(round(k * (n - _TILE_PX) / 2)) // 2) for k in range(3)]

    return [(y, y + _TILE_PX, x, x + _TILE_PX) for y in starts(height) for x in starts(width)]


def processing_blur(camera: CameraModel, K_new: np.ndarray, method: str | None = "bilinear",
                    pattern: str = "RGGB", whole_frame_px: int = _WHOLE_FRAME_PX) -> np.ndarray:
    """Standard deviation per R, G, B (capture pixels) of the Gaussian blur that demosaicing by
    ``method`` and undistortion to ``K_new`` add beyond a pixel's footprint (module docstring).

    Parameters
    ----------
    camera : CameraModel
        The calibrated (distorted) camera of the photographs, at the sensor's full resolution.
    K_new : ndarray, shape (3, 3)
        The capture's pinhole camera, pixels of the built image (half the sensor's for
        ``superpixel``).
    method : str or None
        ``bilinear`` or ``superpixel`` (:data:`abs.acquisition.demosaic.DEMOSAIC_METHODS`);
        ``None`` for photographs that are RGB already (linear EXR frames: undistortion only).
    pattern : str
        A Bayer pattern: the blur does not depend on which (each colour's sites form the same
        lattice up to a shift), but the demosaic needs one.
    whole_frame_px : int
        Sensors of more pixels are measured on tiles (module docstring).

    Returns
    -------
    ndarray, shape (3,)
        Pixels of the built image, >= 0.

    Raises
    ------
    ValueError
        When no built pixel samples the sensor at least two pixels inside its edges.
    """
    h, w = camera.height, camera.width
    superpixel = method == "superpixel"
    built = superpixel_camera(camera) if superpixel else camera
    # Where each built pixel samples, in sensor pixels.
    map_x, map_y, source_x, source_y = sensor_sampling(camera, K_new, superpixel)
    scale = 2 if superpixel else 1  # sensor pixels per pixel of the demosaiced image
    variances = []
    for y0, y1, x0, x1 in _tiles(h, w, whole_frame_px):
        inside = ((source_x >= x0 + _MARGIN_PX) & (source_x <= x1 - 1 - _MARGIN_PX)
                  & (source_y >= y0 + _MARGIN_PX) & (source_y <= y1 - 1 - _MARGIN_PX))
        n = int(inside.sum())
        if n == 0:
            continue
        # The tile's samples, in the coordinates of the tile's (demosaiced) image, in rows.
        rows = -(-n // _ROW)
        mx, my = (np.zeros(rows * _ROW, np.float32) for _ in range(2))
        mx[:n], my[:n] = map_x[inside] - x0 / scale, map_y[inside] - y0 / scale
        mx, my = mx.reshape(rows, _ROW), my.reshape(rows, _ROW)
        v, u = np.mgrid[y0:y1, x0:x1].astype(np.float64)

        def through(image):
            rgb = (np.repeat(image[..., None], 3, axis=-1) if method is None
                   else demosaic(image, pattern, method, np.float64))
            return remap_bilinear(rgb, mx, my, np.float64).reshape(-1, 3)[:n]

        variance = 0.0
        for coordinate in (u, v):
            mean = through(coordinate)
            variance = variance + (through(coordinate * coordinate) - mean * mean) / 2.0
        variances.append(variance)
    if not variances:
        raise ValueError(f"no pixel of the undistorted {built.width}x{built.height} image samples "
                         f"the {w}x{h} sensor {_MARGIN_PX:g} pixels inside its edges")
    var_sensor = np.concatenate(variances).mean(axis=0)
    s = float(K_new[0, 0]) / float(camera.K[0, 0])
    extra = s * s * var_sensor + PIXEL_FOOTPRINT_VARIANCE_PX2 * (s * s - 1.0)
    return np.sqrt(np.maximum(extra, 0.0))
