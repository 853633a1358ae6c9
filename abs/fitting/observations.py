"""Photographs prepared for comparison with renderings: at the compared resolution, with masks.

A fit may compare downsampled images to save time (the seeds fit at low resolution). A camera
downsampled by an integer ``factor`` keeps the OpenCV pixel-centre convention: low-resolution
pixel ``j`` averages high-resolution pixels ``j*f .. j*f+f-1``, whose centre is at
``j*f + (f-1)/2``, hence ``K' = S K`` with ``S = [[1/f, 0, -(f-1)/(2f)], [0, 1/f, -(f-1)/(2f)],
[0, 0, 1]]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.render.camera import Camera

__all__ = ["Observation", "downsample", "downsample_camera", "downsample_mask", "observe",
           "estimate_image_noise"]


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
                  camera.block * factor)


def estimate_image_noise(image: np.ndarray) -> float:
    """Standard deviation of white noise in an image (Immerkaer 1996, "Fast noise variance
    estimation"): the mean absolute response to a Laplacian-difference kernel that cancels
    locally linear signal, averaged over channels."""
    kernel = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float64)
    img = np.asarray(image, np.float64)
    if img.ndim == 2:
        img = img[..., None]
    h, w = img.shape[:2]
    if h < 3 or w < 3:
        return 0.0
    response = np.zeros((h - 2, w - 2, img.shape[2]))
    for dy in range(3):
        for dx in range(3):
            response += kernel[dy, dx] * img[dy:dy + h - 2, dx:dx + w - 2]
    return float(np.sqrt(np.pi / 2.0) * np.abs(response).mean() / 6.0)


@dataclass(frozen=True)
class Observation:
    """One view as compared: camera, photograph and mask at the compared resolution.

    Attributes
    ----------
    name : str
    holdout : bool
    camera : Camera
    photograph : ndarray, shape (H, W, 3)
        Linear RGB.
    mask : ndarray of bool, shape (H, W)
        Compared pixels.
    """

    name: str
    holdout: bool
    camera: Camera
    photograph: np.ndarray
    mask: np.ndarray

    @property
    def pixels(self) -> int:
        return int(self.mask.sum())


def observe(view, factor: int = 1) -> Observation:
    """Read a capture view's photograph (and mask) at ``1/factor`` resolution."""
    photo = view.read_image().astype(np.float64)
    mask = view.read_mask()
    camera = Camera.from_view(view)
    return Observation(view.name, bool(view.holdout), downsample_camera(camera, factor),
                       downsample(photo, factor), downsample_mask(mask, factor))
