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
(and ``y``, ``y^2``) are pushed through the build's own demosaicing and undistortion, in float64,
and ``E[x^2] - E[x]^2`` is read off per pixel and channel. So every detail of the pipeline counts
(the CFA pattern's phase, which sites a superpixel averages, the undistortion's zoom and its
fractional sample positions), and a change to the pipeline changes the blur with it.

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
from abs.acquisition.demosaic import SUPERPIXEL_FROM_FULL, demosaic
from abs.acquisition.undistort import superpixel_camera, undistort_image, undistortion_maps

__all__ = ["PIXEL_FOOTPRINT_VARIANCE_PX2", "processing_blur"]

#: Variance per axis (pixels^2) of the footprint the renderer gives a pixel: its tent filter of
#: radius 1 pixel (abs.render.integrator; tests/test_acquisition_blur.py checks the two agree).
PIXEL_FOOTPRINT_VARIANCE_PX2 = 1.0 / 6.0

# Pixels whose bilinear samples come from this close to the sensor's edge are left out: there the
# demosaic's reflected border and the remap's constant border break "weights sum to one".
_MARGIN_PX = 2.0


def processing_blur(camera: CameraModel, K_new: np.ndarray, method: str | None = "bilinear",
                    pattern: str = "RGGB") -> np.ndarray:
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
        The Bayer pattern (the blur of bilinear demosaicing does not depend on it; the
        superpixels' does not either; given for the sites' exact positions).

    Returns
    -------
    ndarray, shape (3,)
        Pixels of the built image, >= 0.
    """
    h, w = camera.height, camera.width
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    superpixel = method == "superpixel"
    built = superpixel_camera(camera) if superpixel else camera

    def through(image):
        rgb = (np.repeat(image[..., None], 3, axis=-1) if method is None
               else demosaic(image, pattern, method, np.float64))
        return undistort_image(rgb, built, K_new, np.float64)

    variance = 0.0
    for coordinate in (u, v):
        mean = through(coordinate)
        variance = variance + (through(coordinate * coordinate) - mean * mean) / 2.0
    # Where each built pixel samples, in sensor pixels: inside by the margin?
    map_x, map_y = (m.astype(np.float64) for m in undistortion_maps(built, K_new))
    if superpixel:
        full = np.linalg.inv(SUPERPIXEL_FROM_FULL)
        map_x, map_y = full[0, 0] * map_x + full[0, 2], full[1, 1] * map_y + full[1, 2]
    inside = ((map_x >= _MARGIN_PX) & (map_x <= w - 1 - _MARGIN_PX)
              & (map_y >= _MARGIN_PX) & (map_y <= h - 1 - _MARGIN_PX))
    if not inside.any():
        raise ValueError(f"the {w}x{h} camera has no pixel {_MARGIN_PX:g} pixels inside its frame")
    var_sensor = variance[inside].mean(axis=0)
    s = float(K_new[0, 0]) / float(camera.K[0, 0])
    extra = s * s * var_sensor + PIXEL_FOOTPRINT_VARIANCE_PX2 * (s * s - 1.0)
    return np.sqrt(np.maximum(extra, 0.0))
