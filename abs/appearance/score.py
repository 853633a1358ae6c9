"""The metric of issue 29: the structured-light study's CIEDE2000, per object and per θ profile.

Both images are tone-mapped with Reinhard's operator at the *target's* log-average luminance and
a 2.2 gamma (:func:`abs.metrics.reinhard`), converted to CIELAB and compared with CIEDE2000
(:func:`abs.metrics.ciede2000_image`). Two summaries:

- per pixel: mean ± sd of ΔE00 over an object's pixels (Monte-Carlo noise included: two renders
  of one scene with different seeds differ by this much at no change of look, the noise floor);
- per profile: each object's mean linear colour in each θ bin, tone-mapped and compared, the
  bins' ΔE00 averaged with pixel-count weights. Averaging before comparing removes most of the
  noise, so this measures the look.
"""

from __future__ import annotations

import numpy as np

from abs.appearance.geometry import Geometry
from abs.appearance.statistics import object_bins, theta_edges
from abs.metrics import ciede2000_image, log_average_luminance, reinhard

__all__ = ["delta_e_map", "object_scores"]


def delta_e_map(image: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per-pixel ΔE00 ``(h, w)`` of ``image`` against ``target`` (tone-mapped at the target's key)."""
    key = log_average_luminance(target)
    return ciede2000_image(reinhard(target, key), reinhard(image, key))


def object_scores(image: np.ndarray, target: np.ndarray, geometry: Geometry,
                  n_bins: int = 9) -> list[dict]:
    """Per object: class, pixel count, pixel ΔE00 mean and sd, profile ΔE00.

    Parameters
    ----------
    image, target : np.ndarray
        ``(h, w, 3)`` linear RGB; ``target`` is what ``image`` should look like.
    geometry : Geometry
        Objects and θ of the pixels.
    n_bins : int
        θ bins of the profile.
    """
    key = log_average_luminance(target)
    delta = ciede2000_image(reinhard(target, key), reinhard(image, key))
    out = []
    for obj, mask, bins in object_bins(geometry, theta_edges(n_bins)):
        d = delta[mask]
        n = np.bincount(bins, minlength=n_bins)
        has = n > 0
        means = [np.stack([np.bincount(bins, img[mask][:, k], n_bins) for k in range(3)], 1)[has]
                 / n[has, None] for img in (image, target)]
        profile = ciede2000_image(reinhard(means[1], key), reinhard(means[0], key))
        out.append({"object": obj, "class": geometry.classes[obj - 1], "pixels": int(mask.sum()),
                    "mean": float(d.mean()), "sd": float(d.std()),
                    "profile": float(np.sum(profile * n[has]) / n[has].sum())})
    return out
