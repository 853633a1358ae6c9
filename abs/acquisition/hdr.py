"""Merging an exposure bracket of linear frames into one HDR image.

For linear sensor values ``x_i = L * t_i + noise`` (dark frame subtracted), the estimate of the
radiance ``L`` from frame i is ``x_i / t_i``. Frames are weighted by their exposure time ``t_i``
(longer exposures carry more signal per unit of noise), which gives
``L = sum_i x_i / sum_i t_i`` over the frames where the pixel is neither saturated nor dark: the
maximum-likelihood estimate under shot noise. The result is in data numbers per second: radiance
up to the camera's unknown exposure scale, which a scene's ``environment.scale`` absorbs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from abs.errors import InputError

__all__ = ["MergedHDR", "merge_brackets", "check_exposures"]


@dataclass
class MergedHDR:
    """Result of :func:`merge_brackets`.

    Attributes
    ----------
    radiance : np.ndarray
        Merged image, data numbers per second, float32, the frames' shape.
    weight : np.ndarray
        Total exposure time of the frames used per pixel, seconds (0 where none was usable).
    used : np.ndarray
        ``(n_frames, ...)`` boolean: frame i was used at that pixel.
    saturated_everywhere : np.ndarray
        Pixels saturated even in the shortest exposure (their value is a lower bound, taken
        from the shortest exposure).
    variance : np.ndarray
        The radiance's noise variance, (data numbers per second)^2, float32: the frames' shot
        noise at one electron per data number plus their read noise (``read_noise_dn``), carried
        through the merge; at least the value's square where it is a lower bound (saturated
        everywhere). A camera's gain (electrons per data number) scales the shot term, and
        where shot noise dominates (all but the darkest pixels) the values are right up to about
        one factor per camera: enough to weigh pixels against each other (``noise`` of a
        capture, :mod:`abs.io.capture`).
    """

    radiance: np.ndarray
    weight: np.ndarray
    used: np.ndarray
    saturated_everywhere: np.ndarray
    variance: np.ndarray


def check_exposures(exposures_s: Sequence[float], source: str | None = None) -> np.ndarray:
    """Exposure times as an array; they must be positive and strictly increasing."""
    t = np.asarray(exposures_s, np.float64).ravel()
    if t.size == 0 or not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise InputError(source, "exposures", f"exposure times must be positive seconds, got "
                                              f"{t.tolist()}")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        i = int(bad[0])
        raise InputError(source, "exposures", f"exposure times must increase strictly: frame "
                                              f"{i + 1} has {t[i + 1]:g} s after {t[i]:g} s "
                                              "(sort the bracket or drop duplicates)")
    return t


def merge_brackets(frames: Sequence[np.ndarray], exposures_s: Sequence[float],
                   white_level: float, darks: Sequence[np.ndarray] | None = None,
                   saturation: float = 0.95, dark_floor: float = 2.0,
                   saturated: Sequence[np.ndarray] | None = None,
                   source: str | None = None, read_noise_dn: float = 1.0) -> MergedHDR:
    """Merge linear frames of one scene taken at increasing exposure times.

    Parameters
    ----------
    frames : sequence of np.ndarray
        Raw values (data numbers), one array per exposure, all the same shape.
    exposures_s : sequence of float
        Exposure time of each frame, seconds, strictly increasing.
    white_level : float
        Sensor saturation, data numbers.
    darks : sequence of np.ndarray, optional
        Dark frame per exposure (same exposure time, lens capped), subtracted from each frame.
    saturation : float
        A raw value >= ``saturation * white_level`` is saturated and excluded.
    dark_floor : float
        A dark-subtracted value below this many data numbers is too dark and excluded (quantised
        noise, not signal).
    saturated : sequence of np.ndarray, optional
        Per frame, boolean masks of saturated values, replacing the ``saturation`` test (e.g.
        demosaiced pixels interpolated from a clipped mosaic site, see :mod:`.build`).
    source : str, optional
        Where the bracket came from, for error messages.
    read_noise_dn : float
        The frames' read noise (standard deviation, data numbers), for
        :attr:`MergedHDR.variance` only.
    """
    t = check_exposures(exposures_s, source)
    if len(frames) != t.size:
        raise InputError(source, "frames", f"{len(frames)} frames for {t.size} exposure times")
    shapes = [np.shape(f) for f in frames]
    for i, shape in enumerate(shapes[1:], 1):
        if shape != shapes[0]:
            raise InputError(source, f"frames[{i}]", f"mixed image sizes: frame {i} is {shape}, "
                                                     f"frame 0 is {shapes[0]}")
    stack = np.stack([np.asarray(f, np.float64) for f in frames])
    if darks is not None:
        if len(darks) != t.size:
            raise InputError(source, "darks", f"{len(darks)} dark frames for {t.size} exposures")
        for i, d in enumerate(darks):
            try:
                np.broadcast_to(np.asarray(d), stack.shape[1:])
            except ValueError:
                raise InputError(source, f"darks[{i}]", f"mixed image sizes: dark frame {i} is "
                                                        f"{np.shape(d)}, frames are "
                                                        f"{stack.shape[1:]}") from None
        dark = np.stack([np.broadcast_to(np.asarray(d, np.float64), stack.shape[1:])
                         for d in darks])
    else:
        dark = np.zeros_like(stack)
    signal = stack - dark
    if saturated is None:
        saturated = stack >= saturation * white_level
    else:
        saturated = np.stack([np.broadcast_to(np.asarray(m, bool), stack.shape[1:])
                              for m in saturated])
    used = ~saturated & (signal >= dark_floor)
    shape = (-1,) + (1,) * (stack.ndim - 1)
    exposure = np.broadcast_to(t.reshape(shape), stack.shape)
    weight = np.sum(np.where(used, exposure, 0.0), axis=0)
    total = np.sum(np.where(used, signal, 0.0), axis=0)
    radiance = np.divide(total, weight, out=np.zeros_like(total), where=weight > 0)
    # No usable frame: saturated even at the shortest time -> lower bound from that frame;
    # otherwise too dark everywhere -> the longest exposures' sum (best, if noisy, estimate).
    saturated_all = saturated[0] & (weight == 0)
    dark_all = (weight == 0) & ~saturated_all
    radiance = np.where(saturated_all, signal[0] / t[0], radiance)
    radiance = np.where(dark_all, np.sum(np.where(saturated, 0.0, signal), axis=0) / t.sum(),
                        radiance)
    # Shot noise (variance = counts) and read noise of the frames summed, over the squared total
    # exposure: the variance of ``total / weight`` (and of the two fallbacks' own sums).
    read = float(read_noise_dn) ** 2
    counts = np.maximum(signal, 0.0)
    variance = (np.sum(np.where(used, counts + read, 0.0), axis=0)
                / np.where(weight > 0, weight, 1.0) ** 2)
    # A value saturated in every frame is a lower bound: its error is as large as itself.
    variance = np.where(saturated_all, np.maximum((counts[0] + read) / t[0] ** 2,
                                                  np.square(radiance)), variance)
    unsaturated = ~saturated
    variance = np.where(dark_all, np.sum(np.where(unsaturated, counts + read, 0.0), axis=0)
                        / t.sum() ** 2, variance)
    return MergedHDR(radiance.astype(np.float32), weight.astype(np.float32), used, saturated_all,
                     np.maximum(variance, read / t.sum() ** 2).astype(np.float32))
