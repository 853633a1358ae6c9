"""The normal step: how a renderer shares a θ bin's light out over the normal's azimuth φ.

The paper (issue 29) looks a pixel's filter up by its normal, (θ, φ); α, λ, ψ resolve θ only.
That loses what a glossy or mirror-like class shows at one θ: the environment reflected in it,
bright sky above and dark ground below. A renderer whose lobes are narrower than A's (the
reconfigured Mitsuba's alpha = roughness² against abs's alpha = roughness) shows those reflections
sharper: at the same θ, more light at the φ that faces the sky and less at the φ that faces the
ground. No per-θ statistic can move light between pixels of one bin; the benchmark measured that
the per-pixel error left after the θ transfer to Mitsuba is mostly there (metal spheres,
docs/appearance.md).

So, per class c, θ bin b and azimuth bin p (φ: the world normal's direction about the world z
axis, ``atan2(n_x, n_y)``, 0 pointing up; the design camera looks along −z, so this is the
normal's direction in the image from "up"), with ``S`` the sum of radiance and ``n`` the pixel
count of class c's objects in that cell over the design::

    g(c, b, p) = (S_B(b, p) / S_B(b)) / (S_A(b, p) / S_A(b))

per channel: how much more of the bin's light B puts at that φ than A does. After the θ transfer
each pixel is multiplied by the gain of its cell, and then each object's θ bin is scaled back to
the mean the θ transfer gave it, so the step only redistributes light within a bin.

This holds only under the characterisation's own lighting: where the reflections fall depends on
where the environment is bright. Use it for images lit by the environment the design was rendered
under, in the same orientation (the benchmark's held-out scenes are); it is off by default.

A class gets the step only where it predicts: the design's scenes are split into two halves
(alternate scenes, so each half has every sample and half the wall colourings), the gains of one
half predict the other's cells, and the class is used only if that prediction is closer (count-
weighted squared log error) than no step at all, both ways summed. A renderer against itself
(Monte-Carlo noise only) fails that test, so the step leaves it untouched.
"""

from __future__ import annotations

import numpy as np

from abs.appearance.geometry import Geometry

__all__ = ["PHI_BINS", "phi_bins", "normal_gains", "apply_normal_gains"]

PHI_BINS = 24
"""Azimuth bins over [−π, π) (15° each) of the stored sums (``phi_sums``, ``phi_counts``)."""

_GAIN_LIMIT = 10.0  # a cell's gain is clipped to [1/10, 10]: a few noisy pixels must not zero a pixel


def phi_bins(normals: np.ndarray, n_phi: int = PHI_BINS) -> np.ndarray:
    """Azimuth bin of each world normal ``(..., 3)`` (see the module docstring), ``(...)`` ints."""
    phi = np.arctan2(normals[..., 0], normals[..., 1])  # in [−π, π]; π is −π (straight down)
    return np.floor((phi + np.pi) / (2.0 * np.pi) * n_phi).astype(int) % n_phi


def _gains(sums_a: np.ndarray, n_a: np.ndarray, sums_b: np.ndarray, n_b: np.ndarray) -> np.ndarray:
    """``(B, P, 3)`` gains from pooled sums ``(B, P, 3)`` and counts ``(B, P)``; 1 where unknown."""
    with np.errstate(invalid="ignore", divide="ignore"):
        share_a = sums_a / sums_a.sum(axis=1, keepdims=True)
        share_b = sums_b / sums_b.sum(axis=1, keepdims=True)
        g = share_b / share_a
    known = (n_a > 0) & (n_b > 0)
    g = np.where(known[..., None] & np.isfinite(g) & (g > 0), g, 1.0)
    return np.clip(g, 1.0 / _GAIN_LIMIT, _GAIN_LIMIT)


def normal_gains(source, target) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """Per class, the gains ``(B, P, 3)`` of the normal step, for the classes that pass the split
    test; and, per class, that test's errors (``{"with": e1, "without": e0, "used": bool}``).

    Parameters
    ----------
    source, target : Characterisation
        Renderer A's and B's, on one design (the split pairs their scenes by index), both with
        ``phi_sums`` and ``phi_counts``.
    """
    gains, report = {}, {}
    n_scenes = len(source.phi_counts)
    halves = [np.arange(n_scenes) % 2 == 0, np.arange(n_scenes) % 2 == 1]
    for cls in source.classes:
        ca, cb = source.class_index(cls), target.class_index(cls)
        if cb is None:
            continue

        def pooled(scenes):
            return (source.phi_sums[scenes, ca].sum(0), source.phi_counts[scenes, ca].sum(0),
                    target.phi_sums[scenes, cb].sum(0), target.phi_counts[scenes, cb].sum(0))

        with_step = without = 0.0
        for fit, test in (halves, halves[::-1]):
            held_out = pooled(test)
            predicted, truth = _gains(*pooled(fit)), _gains(*held_out)
            weight = held_out[1][..., None]
            with_step += float(np.sum(weight * np.log(truth / predicted) ** 2))
            without += float(np.sum(weight * np.log(truth) ** 2))
        used = with_step < without
        report[cls] = {"with": with_step, "without": without, "used": bool(used)}
        if used:
            gains[cls] = _gains(*pooled(slice(None)))
    return gains, report


def apply_normal_gains(image: np.ndarray, geometry: Geometry, gains: dict[str, np.ndarray],
                       edges: np.ndarray) -> np.ndarray:
    """``image`` with each object's pixels multiplied by its class's cell gains, then each θ bin
    scaled back to its mean before (per object and channel); classes without gains untouched."""
    from abs.appearance.statistics import object_bins

    out = np.array(image, np.float64)
    n_phi = next(iter(gains.values())).shape[1] if gains else PHI_BINS
    phi = phi_bins(geometry.normals, n_phi)
    for obj, mask, bins in object_bins(geometry, edges):
        g = gains.get(geometry.classes[obj - 1])
        if g is None:
            continue
        x = out[mask]
        y = x * g[bins, phi[mask]]
        n_bins = len(edges) - 1
        for k in range(3):
            before = np.bincount(bins, x[:, k], n_bins)
            after = np.bincount(bins, y[:, k], n_bins)
            scale = np.where(after > 0, before / np.where(after > 0, after, 1.0), 1.0)
            y[:, k] *= scale[bins]
        out[mask] = y
    return out
