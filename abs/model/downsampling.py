"""Images and cameras at a reduced resolution, consistently with each other.

A fit may compare downsampled images to save time (the seeds fit at low resolution), so the
photograph, its mask and the camera that renders it must be reduced alike. A camera downsampled
by an integer ``factor`` keeps the OpenCV pixel-centre convention: low-resolution pixel ``j``
averages high-resolution pixels ``j*f .. j*f+f-1``, whose centre is at ``j*f + (f-1)/2``, hence
``K' = S K`` with ``S = [[1/f, 0, -(f-1)/(2f)], [0, 1/f, -(f-1)/(2f)], [0, 0, 1]]``.
"""

from __future__ import annotations

import numpy as np

from abs.render.camera import Camera

__all__ = ["downsample", "downsample_camera", "downsample_mask"]


def downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """Box-average ``image`` (H, W, ...) by an integer factor (the remainder is cropped)."""
    if factor == 1:
        return image
    h, w = image.shape[0] // factor, image.shape[1] // factor
    cropped = image[: h * factor, : w * factor]
    return cropped.reshape(h, factor, w, factor, *image.shape[2:]).mean(axis=(1, 3))


def downsample_mask(mask: np.ndarray, factor: int) -> np.ndarray:
    """A low-resolution pixel is compared only if all its high-resolution pixels are."""
    if factor == 1:
        return mask
    return downsample(mask.astype(np.float64), factor) > 1.0 - 1e-9


def downsample_camera(camera: Camera, factor: int) -> Camera:
    """The camera whose pixels are ``factor`` x ``factor`` blocks of ``camera``'s."""
    if factor == 1:
        return camera
    shift = -(factor - 1) / (2.0 * factor)
    S = np.array([[1.0 / factor, 0.0, shift], [0.0, 1.0 / factor, shift], [0.0, 0.0, 1.0]])
    return Camera(S @ camera.K, camera.R, camera.t, camera.width // factor, camera.height // factor,
                  camera.block * factor, camera.blur_px, footprint=camera.footprint)
