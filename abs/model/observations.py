"""Photographs prepared for comparison with renderings: at the compared resolution, with masks.

A view of a capture is files on disk (an image, a mask, calibration); the residuals need arrays
at the resolution the renderer is asked for. :func:`observe` reads a view once and reduces it
(:mod:`abs.model.downsampling`), so that every problem built over the same views compares the
same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.model.downsampling import downsample, downsample_camera, downsample_mask
from abs.render.camera import Camera

__all__ = ["Observation", "observe"]


@dataclass(frozen=True)
class Observation:
    """One view as compared: camera, photograph and mask at the compared resolution.

    Attributes
    ----------
    name : str
        The view's name in ``cameras.json``.
    holdout : bool
        Kept out of fitting (evaluated only).
    camera : Camera
        The camera at the compared resolution (pixels).
    photograph : ndarray, shape (H, W, 3)
        Linear RGB (relative radiance, unitless).
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
    """Read a capture view's photograph (and mask) at ``1/factor`` resolution.

    Parameters
    ----------
    view : abs.io.capture.View
        A view of a loaded capture.
    factor : int
        Integer downsampling factor (1: full resolution).

    Returns
    -------
    Observation
    """
    photo = view.read_image().astype(np.float64)
    mask = view.read_mask()
    camera = Camera.from_view(view)
    return Observation(view.name, bool(view.holdout), downsample_camera(camera, factor),
                       downsample(photo, factor), downsample_mask(mask, factor))
