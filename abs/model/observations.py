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

__all__ = ["Observation", "observe", "boost_where_seen", "seen_rectangle", "pixel_weights"]

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
    noise_sd : ndarray, shape (H, W, 3), or None
        The photograph's noise standard deviation per pixel and channel, up to a factor common
        to the capture (the capture's ``noise``), or ``None`` (pixels weigh alike).
    """

    name: str
    holdout: bool
    camera: Camera
    photograph: np.ndarray
    mask: np.ndarray
    noise_sd: np.ndarray | None = None

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
    sd = view.read_noise()
    if sd is not None:
        # The noise of a block's mean (independent pixels; only ratios matter).
        sd = np.sqrt(downsample(np.square(sd), factor)) / factor
    return Observation(view.name, bool(view.holdout), downsample_camera(camera, factor),
                       downsample(photo, factor), downsample_mask(mask, factor), sd)


def pixel_weights(observations) -> list[np.ndarray] | None:
    """Weights of each observation's residuals, ``(H, W, 3)`` (0 outside the mask):
    ``sqrt(2) s / sqrt(sd^2 + s^2)``, ``sd`` the photograph's noise standard deviation of that
    pixel and channel and ``s`` its median over every compared pixel and channel of
    ``observations``. ``None`` unless every observation has a noise image (a capture's
    ``noise``): weights on some views only would set those views' scale against the others'
    arbitrarily.

    Weighted least squares is the maximum-likelihood fit when the noise differs between pixels:
    in a photograph merged from brackets the noise grows with the light, and a bright glint's
    pixels, left at equal weight, outweigh the rest of the image (docs/fitting.md, Pixel
    weights). The noise image holds the photograph's noise only; the residuals also hold the
    renders' Monte-Carlo noise (at a fit's samples per pixel about the photograph's typical
    noise, or more) and whatever the model gets wrong, neither of which falls with the light.
    So each pixel's variance is taken as its own plus the median one, ``s^2``: the noisiest
    pixels count for little, the quietest at most twice the median one's (measured, the glass
    suite's raw-built sphere and the acquisition benchmark's builds: without that floor, dark
    pixels took over fits whose model is approximate). A typical pixel weighs 1, so that a
    weighted residual is in the photograph's units and noise estimates from the photographs
    still apply to it.
    """
    if not observations or any(o.noise_sd is None for o in observations):
        return None
    reference = float(np.median(np.concatenate([o.noise_sd[o.mask].ravel() for o in observations])))
    return [np.where(o.mask[..., None],
                     np.sqrt(2.0) * reference / np.hypot(o.noise_sd, reference), 0.0)
            for o in observations]


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
