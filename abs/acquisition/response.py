"""Non-linear (8-bit, JPEG) brackets: Debevec's camera response recovery and merge.

Only for inputs that are not linear: raw mosaics and EXR frames go through
:func:`abs.acquisition.hdr.merge_brackets`. OpenCV's ``CalibrateDebevec`` recovers the inverse
response (code -> relative exposure, per channel) from the bracket itself, and ``MergeDebevec``
merges with its hat weighting. The result is relative radiance per second, with the same unknown
scale as any HDR merge (absorbed by ``environment.scale``).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from abs.acquisition.hdr import check_exposures
from abs.errors import InputError

__all__ = ["recover_response", "merge_ldr"]


def _as_bgr8(images: Sequence[np.ndarray], source: str | None) -> list[np.ndarray]:
    out = []
    for i, img in enumerate(images):
        img = np.asarray(img)
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            raise InputError(source, f"frames[{i}]", f"expected (H, W, 3) uint8 RGB, got "
                                                     f"{img.shape} {img.dtype}")
        if out and img.shape != out[0].shape:
            raise InputError(source, f"frames[{i}]", f"mixed image sizes: {img.shape[:2]} and "
                                                     f"{out[0].shape[:2]}")
        out.append(np.ascontiguousarray(img[..., ::-1]))  # OpenCV works in BGR
    return out


def recover_response(images: Sequence[np.ndarray], exposures_s: Sequence[float],
                     samples: int = 200, smoothness: float = 10.0,
                     source: str | None = None) -> np.ndarray:
    """Inverse camera response from an 8-bit bracket (Debevec & Malik 1997, OpenCV).

    Parameters
    ----------
    images : sequence of np.ndarray
        ``(H, W, 3)`` uint8 RGB frames of a still scene.
    exposures_s : sequence of float
        Exposure times, seconds, strictly increasing.
    samples : int
        Pixel locations used by the fit.
    smoothness : float
        Weight of the response's second-derivative penalty.

    Returns
    -------
    np.ndarray
        ``(256, 3)`` float32: relative exposure (linear) of each code value, R, G, B.
    """
    t = check_exposures(exposures_s, source)
    bgr = _as_bgr8(images, source)
    calibrate = cv2.createCalibrateDebevec(samples, smoothness, False)
    response = calibrate.process(bgr, t.astype(np.float32))
    return np.asarray(response, np.float32).reshape(256, 3)[:, ::-1].copy()


def merge_ldr(images: Sequence[np.ndarray], exposures_s: Sequence[float],
              response: np.ndarray, source: str | None = None) -> np.ndarray:
    """Merge an 8-bit bracket into relative linear radiance with a recovered response.

    Returns
    -------
    np.ndarray
        ``(H, W, 3)`` float32 RGB, relative radiance per second.
    """
    t = check_exposures(exposures_s, source)
    bgr = _as_bgr8(images, source)
    bgr_response = np.ascontiguousarray(np.asarray(response, np.float32)[:, ::-1]).reshape(256, 1, 3)
    merged = cv2.createMergeDebevec().process(bgr, t.astype(np.float32), bgr_response)
    return np.asarray(merged, np.float32)[..., ::-1].copy()
