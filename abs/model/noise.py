"""The white-noise level of an image, from the image alone.

A fit weighs pixels against priors, and its checks judge the final misfit, by the noise a perfect
model would leave: the photograph's sensor noise plus the rendering's Monte-Carlo noise. Neither
is known in advance, so both are estimated from the images themselves.

The estimate assumes noise independent from pixel to pixel. A photograph built from a raw sensor
is not: demosaicing interpolates a site's noise into its neighbours, which the estimator's
Laplacian largely cancels (a bilinear build's noise reads a third to a sixth of its true level:
the glass benchmark's raw-built sphere, a flat test in tests/test_footprint.py). For a camera
that renders the build's processing (a footprint) the estimate is scaled by what the build's own
weights do to independent site noise, measured once per camera by pushing white noise through
them; a footprint rendering's Monte-Carlo noise, made per site and spread alike, gets the same.
There the median response is used: the noise's own response being several times smaller, the
mean would read the signal's edges instead.
"""

from __future__ import annotations

from weakref import WeakKeyDictionary

import numpy as np

__all__ = ["estimate_image_noise"]

_GAINS: WeakKeyDictionary = WeakKeyDictionary()


def estimate_image_noise(image: np.ndarray, camera=None) -> float:
    """Standard deviation of the noise in an image (Immerkaer 1996, "Fast noise variance
    estimation"): the mean absolute response to a Laplacian-difference kernel that cancels
    locally linear signal, averaged over channels.

    ``camera`` (an :class:`abs.render.Camera`, optional): when it renders a built capture's
    processing (``camera.footprint``), the estimate is corrected for the noise's correlation
    between pixels (module docstring): the per-pixel standard deviation, as for white noise.
    """
    if camera is not None and camera.footprint is not None:
        # The median response: with the noise's own response shrunk by its correlation, the
        # mean would be the signal's edges (and a bilinear build's borders) times the gain.
        return _immerkaer(image, robust=True) * _correlation_gain(camera)
    return _immerkaer(image)


def _correlation_gain(camera) -> float:
    """True per-pixel standard deviation over Immerkaer's estimate for independent unit noise
    on the sensor sites, pushed through ``camera``'s footprint (its block and size)."""
    film = camera.film()
    if film not in _GAINS:
        rng = np.random.default_rng(0)
        noise = film.apply_numpy(rng.normal(size=(film.sites, 3)))
        _GAINS[film] = film.white_noise_std() / max(_immerkaer(noise, robust=True), 1e-12)
    return _GAINS[film]


def _immerkaer(image: np.ndarray, robust: bool = False) -> float:
    """Immerkaer's estimate; ``robust``: from the median absolute response (Gaussian noise:
    0.6745 sigma) rather than the mean, so that a few strong edges do not count."""
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
    if robust:
        return float(np.median(np.abs(response)) / 0.6745 / 6.0)
    return float(np.sqrt(np.pi / 2.0) * np.abs(response).mean() / 6.0)
