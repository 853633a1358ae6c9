"""Photographs prepared for comparison with renderings: at the compared resolution, with masks.

A view of a capture is files on disk (an image, a mask, calibration); the residuals need arrays
at the resolution the renderer is asked for. :func:`observe` reads a view once and reduces it
(:mod:`abs.model.downsampling`), so that every problem built over the same views compares the
same pixels.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from abs.model.downsampling import downsample, downsample_camera, downsample_mask
from abs.render.camera import Camera, SampleBoost

__all__ = ["Observation", "observe", "boost_where_seen", "seen_rectangle"]

#: Pixels added around a boosted rectangle: a pixel's filter reaches its neighbours.
BOOST_MARGIN_PX = 2


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


def seen_rectangle(camera: Camera, bounds) -> tuple[int, int, int, int] | None:
    """The pixels ``(x0, y0, x1, y1)`` (``[y0:y1, x0:x1]``) where the boxes ``bounds``
    (``(lower, upper)`` world corners, m) are seen by ``camera``: the rectangle around their
    projected corners, :data:`BOOST_MARGIN_PX` wider, cut to the image.

    ``None`` for no boxes, boxes that reach behind the camera (no rectangle bounds what such a box
    covers) or boxes outside the image.
    """
    if not bounds:
        return None
    corners = np.array([c for lo, hi in bounds for c in itertools.product(*zip(lo, hi))], float)
    in_camera = corners @ camera.R.T + np.ravel(camera.t)
    if np.any(in_camera[:, 2] <= 0):
        return None
    uv = in_camera @ camera.K.T
    u, v = uv[:, 0] / uv[:, 2], uv[:, 1] / uv[:, 2]
    x0 = max(0, int(np.floor(u.min())) - BOOST_MARGIN_PX)
    y0 = max(0, int(np.floor(v.min())) - BOOST_MARGIN_PX)
    x1 = min(camera.width, int(np.ceil(u.max())) + 1 + BOOST_MARGIN_PX)
    y1 = min(camera.height, int(np.ceil(v.max())) + 1 + BOOST_MARGIN_PX)
    return None if x0 >= x1 or y0 >= y1 else (x0, y0, x1, y1)


def boost_where_seen(observation: Observation, bounds, factor: int) -> Observation:
    """The observation whose camera takes ``factor`` times the samples per pixel where the boxes
    ``bounds`` (``(lower, upper)`` world corners, m; a scene's glass objects) are seen
    (:func:`seen_rectangle`).

    Unchanged for ``factor`` 1 or where :func:`seen_rectangle` gives none. A camera that renders
    a capture's sensor sites (a footprint) boosts the sites the rectangle's pixels use.
    """
    camera = observation.camera
    rectangle = seen_rectangle(camera, bounds) if factor > 1 else None
    if rectangle is None:
        return observation
    return replace(observation, camera=replace(camera, boost=SampleBoost(*rectangle, int(factor))))
