"""Undistortion: from a camera with lens distortion to the capture contract's pinhole.

The new pinhole K comes from ``getOptimalNewCameraMatrix`` with ``alpha = 0`` (only valid
pixels, the image size kept): the focal length and the principal point move as undistortion
moves them, and the undistorted image is resampled with ``initUndistortRectifyMap`` + ``remap``
(bilinear). R and t are unchanged: undistortion does not move the camera.

A superpixel-demosaiced image (:func:`abs.acquisition.demosaic.demosaic_superpixel`) is undistorted
with :func:`superpixel_camera`, the calibrated camera at half resolution.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.acquisition.camera_file import CameraModel
from abs.acquisition.demosaic import SUPERPIXEL_FROM_FULL, superpixel_K
from abs.errors import InputError

__all__ = ["pinhole_K", "remap_bilinear", "sensor_sampling", "superpixel_camera",
           "undistort_image", "undistort_mask", "undistortion_maps"]


def superpixel_camera(camera: CameraModel) -> CameraModel:
    """The calibrated (distorted) camera of a superpixel image: half the width and height, K by
    :func:`abs.acquisition.demosaic.superpixel_K` (focal lengths halved, principal point
    ``(c - 0.5) / 2``), the same distortion coefficients (they act on normalised coordinates),
    R and t unchanged; ``rms_px`` halved."""
    if camera.width % 2 or camera.height % 2:
        raise InputError(None, "camera", f"the camera is {camera.width}x{camera.height} pixels; "
                                         "superpixel images need an even width and height")
    return CameraModel(camera.width // 2, camera.height // 2, superpixel_K(camera.K),
                       np.array(camera.distortion, np.float64), np.array(camera.R, np.float64),
                       np.array(camera.t, np.float64),
                       None if camera.rms_px is None else camera.rms_px / 2)


def pinhole_K(camera: CameraModel, alpha: float = 0.0) -> np.ndarray:
    """The distortion-free camera matrix of the undistorted image (same size), pixels.

    Parameters
    ----------
    camera : CameraModel
        The calibrated camera.
    alpha : float
        0 keeps only valid pixels (no black borders), 1 keeps every source pixel.
    """
    size = (camera.width, camera.height)
    K_new, _ = cv2.getOptimalNewCameraMatrix(camera.K, camera.distortion, size, alpha, size)
    return np.asarray(K_new, np.float64)


def undistortion_maps(camera: CameraModel, K_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of the undistorted image (pinhole ``K_new``, the camera's size), the position
    ``(x, y)`` in the distorted image that it samples: two ``(H, W)`` float32 arrays, pixels."""
    return cv2.initUndistortRectifyMap(camera.K, camera.distortion, None, K_new,
                                       (camera.width, camera.height), cv2.CV_32FC1)


def sensor_sampling(camera: CameraModel, K_new: np.ndarray, superpixel: bool = False):
    """The undistortion maps of a build and where each built pixel samples the sensor.

    Returns ``(map_x, map_y, source_x, source_y)``: the maps into the demosaiced image (float32,
    its pixels; half resolution for superpixels, ``camera`` being the full-resolution sensor's)
    and the same positions in full-resolution sensor pixels (float64).
    """
    built = superpixel_camera(camera) if superpixel else camera
    map_x, map_y = undistortion_maps(built, K_new)
    source_x, source_y = map_x.astype(np.float64), map_y.astype(np.float64)
    if superpixel:
        full = np.linalg.inv(SUPERPIXEL_FROM_FULL)
        source_x, source_y = full[0, 0] * source_x + full[0, 2], full[1, 1] * source_y + full[1, 2]
    return map_x, map_y, source_x, source_y


def remap_bilinear(image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray,
                   dtype=np.float32) -> np.ndarray:
    """``image`` (H, W[, C]) sampled bilinearly at ``(map_x, map_y)`` (pixels, float32 arrays of
    the output's shape), 0 outside, as ``dtype`` (float64 for exact moments, :mod:`.blur`):
    undistortion's resampling."""
    return cv2.remap(np.asarray(image, dtype), map_x, map_y, cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT)


def undistort_image(image: np.ndarray, camera: CameraModel, K_new: np.ndarray) -> np.ndarray:
    """Resample ``image`` (H, W[, C], float) as seen by the pinhole ``K_new`` (bilinear)."""
    if image.shape[:2] != (camera.height, camera.width):
        raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, camera "
                         f"{camera.width}x{camera.height}")
    return remap_bilinear(image, *undistortion_maps(camera, K_new))


def undistort_mask(mask: np.ndarray, camera: CameraModel, K_new: np.ndarray) -> np.ndarray:
    """Resample a boolean ``(H, W)`` mask like :func:`undistort_image` (nearest neighbour); pixels
    that come from outside the original frame are False."""
    if mask.shape[:2] != (camera.height, camera.width):
        raise ValueError(f"mask is {mask.shape[1]}x{mask.shape[0]}, camera "
                         f"{camera.width}x{camera.height}")
    map1, map2 = undistortion_maps(camera, K_new)
    out = cv2.remap(np.asarray(mask, bool).astype(np.uint8), map1, map2, cv2.INTER_NEAREST,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out.astype(bool)
