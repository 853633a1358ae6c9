"""The per-class filter statistics α(θ), λ(θ), ψ(θ) of a renderer, and its histograms.

After the tool-independent appearance paper (issue 29), a renderer R is a filter on what a
scene "really" looks like: ``I_R = M * L * f_R``. For each material class c, colour channel k and
θ bin b (θ: the angle between the surface normal and the direction to the camera), over the
pixels of every object of class c in every characterisation image:

- energy ``Γ(I_R) = Γ(L_φ) α(θ)``: ``α = Σ I / Σ L``, the bin's light relative to the lighting term
  L (:mod:`abs.appearance.lighting`), pooled over the scenes;
- mean shift ``μ(Ī_R) = μ(L̄_φ) − λ(θ)`` and spread ``σ²(Ī_R) = σ²(L̄_φ) + ψ(θ)`` (ψ an additive
  variance). Barred quantities are normalised by the object's energy: each pixel divided by the
  mean of its object's pixels over all θ, in that image and channel. So α carries how much light
  the renderer gives a class at each θ, λ how the profile over θ is shaped beside the lighting's,
  and ψ how much the pixels of a bin spread beyond the lighting's own spread (texture, glints,
  Monte-Carlo noise). λ and ψ are means over objects of the per-object differences, so that
  differences between scenes do not enter them.

Beside them, for the histogram-matching baselines the paper shows to fail: per channel, the
histogram of log10 radiance over all object pixels (global) and per class (local); for the
sensor step (:mod:`abs.appearance.sensor`), each image's means over a coarse grid of blocks; and
for the normal step (:mod:`abs.appearance.normals`), per scene the sums of each class's radiance
in cells of θ and the normal's azimuth φ.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abs.appearance.geometry import Geometry
from abs.appearance.normals import PHI_BINS, phi_bins
from abs.appearance.sensor import block_means

__all__ = ["Characterisation", "Accumulator", "bin_moments", "object_bins", "theta_edges",
           "HIST_EDGES", "LOG_FLOOR"]

LOG_FLOOR = 1e-4
"""Radiance below this is counted at the floor in the log histograms."""

HIST_EDGES = np.linspace(-4.0, 2.0, 241)
"""Edges of the histograms, log10 of linear radiance (0.025 decades a bin)."""


def theta_edges(n_bins: int) -> np.ndarray:
    """``n_bins + 1`` equal θ bin edges over [0, π/2], radians."""
    return np.linspace(0.0, np.pi / 2, n_bins + 1)


@dataclass(frozen=True)
class Characterisation:
    """A renderer's filter statistics on one design (the file format: docs/appearance.md).

    Attributes
    ----------
    renderer : str
        Registered renderer name; ``options`` its options.
    design : str
        Digest of the scene design (:func:`abs.appearance.design.design_digest`).
    classes : tuple of str
        Material classes, the first axis of the per-class arrays.
    theta_edges : np.ndarray
        ``(n_bins + 1,)`` radians.
    alpha, lam, psi : np.ndarray
        ``(n_classes, n_bins, 3)``: α (1), λ (1), ψ (1, a variance); NaN where ``counts`` is 0.
    counts : np.ndarray
        ``(n_classes, n_bins)`` pixels behind each bin.
    profiles : np.ndarray
        ``(n_scenes, n_classes, n_bins, 3)`` mean radiance of each scene's objects of a class in
        a bin (NaN where none); ``profile_counts`` their pixel counts.
    hist_global : np.ndarray
        ``(3, n_hist)`` pixel counts per :data:`HIST_EDGES` bin; ``hist_local`` per class,
        ``(n_classes, 3, n_hist)``.
    settings : dict
        How it was made (image size, spp, seed, environment).
    blocks : np.ndarray or None
        ``(n_scenes, g, g, 3)`` each scene's whole image (every pixel) averaged over a g x g grid
        of equal blocks, linear radiance (:func:`abs.appearance.sensor.block_means`), for the
        sensor step; None in files written before it existed.
    phi_sums, phi_counts : np.ndarray or None
        ``(n_scenes, n_classes, n_bins, n_phi, 3)`` summed linear radiance and
        ``(n_scenes, n_classes, n_bins, n_phi)`` pixel counts per θ bin and azimuth bin
        (:func:`abs.appearance.normals.phi_bins`), for the normal step; None in older files.
    """

    renderer: str
    options: dict
    design: str
    classes: tuple[str, ...]
    theta_edges: np.ndarray
    alpha: np.ndarray
    lam: np.ndarray
    psi: np.ndarray
    counts: np.ndarray
    profiles: np.ndarray
    profile_counts: np.ndarray
    hist_global: np.ndarray
    hist_local: np.ndarray
    settings: dict = field(default_factory=dict)
    blocks: np.ndarray | None = None
    phi_sums: np.ndarray | None = None
    phi_counts: np.ndarray | None = None

    @property
    def n_bins(self) -> int:
        return len(self.theta_edges) - 1

    def class_index(self, material_class: str) -> int | None:
        return self.classes.index(material_class) if material_class in self.classes else None


def object_bins(geometry: Geometry, edges: np.ndarray):
    """Per object id: its pixel mask and each pixel's θ bin (``(id, mask, bins)`` tuples)."""
    n_bins = len(edges) - 1
    for obj in range(1, len(geometry.classes) + 1):
        mask = geometry.ids == obj
        if mask.any():
            bins = np.clip(np.digitize(geometry.theta[mask], edges) - 1, 0, n_bins - 1)
            yield obj, mask, bins


def bin_moments(values: np.ndarray, bins: np.ndarray, n_bins: int):
    """Count, mean and variance per bin of ``values (n, 3)``: ``(n_bins,)``, ``(n_bins, 3)`` x 2."""
    n = np.bincount(bins, minlength=n_bins).astype(float)
    s1 = np.stack([np.bincount(bins, values[:, k], n_bins) for k in range(3)], axis=1)
    s2 = np.stack([np.bincount(bins, values[:, k] ** 2, n_bins) for k in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / n[:, None]
        var = np.maximum(s2 / n[:, None] - mean ** 2, 0.0)
    return n, mean, var


class Accumulator:
    """Gathers the statistics scene by scene (so images need not be kept), then finishes them.

    Parameters
    ----------
    classes : tuple of str
        The design's material classes.
    n_bins : int
        θ bins over [0, π/2].
    """

    def __init__(self, classes: tuple[str, ...], n_bins: int):
        self.classes = tuple(classes)
        self.edges = theta_edges(n_bins)
        shape = (len(self.classes), n_bins)
        self.n = np.zeros(shape)
        self.sum_image = np.zeros(shape + (3,))
        self.sum_light = np.zeros(shape + (3,))
        self.sum_shift = np.zeros(shape + (3,))
        self.sum_spread = np.zeros(shape + (3,))
        self.profiles: list[np.ndarray] = []
        self.profile_counts: list[np.ndarray] = []
        self.blocks: list[np.ndarray] = []
        self.phi_sums: list[np.ndarray] = []
        self.phi_counts: list[np.ndarray] = []
        n_hist = len(HIST_EDGES) - 1
        self.hist_global = np.zeros((3, n_hist))
        self.hist_local = np.zeros((len(self.classes), 3, n_hist))

    def add(self, image: np.ndarray, geometry: Geometry, lighting: np.ndarray) -> None:
        """One image ``(h, w, 3)`` with its geometry and lighting term ``(h, w, 3)``."""
        n_bins = len(self.edges) - 1
        sums = np.zeros((len(self.classes), n_bins, 3))
        counts = np.zeros((len(self.classes), n_bins))
        phi_sums = np.zeros((len(self.classes), n_bins * PHI_BINS, 3))
        phi_counts = np.zeros((len(self.classes), n_bins * PHI_BINS))
        phi = phi_bins(geometry.normals)
        for obj, mask, bins in object_bins(geometry, self.edges):
            c = self.classes.index(geometry.classes[obj - 1])
            pixels = image[mask].astype(np.float64)
            light = lighting[mask].astype(np.float64)
            energy, light_energy = pixels.mean(axis=0), light.mean(axis=0)
            n, mean_i, _ = bin_moments(pixels, bins, n_bins)
            _, mean_l, _ = bin_moments(light, bins, n_bins)
            _, mean_ib, var_ib = bin_moments(pixels / np.where(energy > 0, energy, 1.0), bins, n_bins)
            _, mean_lb, var_lb = bin_moments(light / np.where(light_energy > 0, light_energy, 1.0),
                                              bins, n_bins)
            has = n > 0
            self.n[c, has] += n[has]
            self.sum_image[c, has] += n[has, None] * mean_i[has]
            self.sum_light[c, has] += n[has, None] * mean_l[has]
            self.sum_shift[c, has] += n[has, None] * (mean_lb[has] - mean_ib[has])
            self.sum_spread[c, has] += n[has, None] * (var_ib[has] - var_lb[has])
            sums[c, has] += n[has, None] * mean_i[has]
            counts[c, has] += n[has]
            cell = bins * PHI_BINS + phi[mask]
            phi_counts[c] += np.bincount(cell, minlength=n_bins * PHI_BINS)
            for k in range(3):
                phi_sums[c, :, k] += np.bincount(cell, pixels[:, k], n_bins * PHI_BINS)
            logs = np.log10(np.maximum(pixels, LOG_FLOOR))
            for k in range(3):
                h = np.histogram(np.clip(logs[:, k], HIST_EDGES[0], HIST_EDGES[-1]), HIST_EDGES)[0]
                self.hist_global[k] += h
                self.hist_local[c, k] += h
        with np.errstate(invalid="ignore", divide="ignore"):
            self.profiles.append(sums / counts[..., None])
        self.profile_counts.append(counts)
        self.blocks.append(block_means(image))
        self.phi_sums.append(phi_sums.reshape(len(self.classes), n_bins, PHI_BINS, 3))
        self.phi_counts.append(phi_counts.reshape(len(self.classes), n_bins, PHI_BINS))

    def finish(self, renderer: str, options: dict, design: str, settings: dict) -> Characterisation:
        """The :class:`Characterisation` of everything added."""
        n = self.n[..., None]
        with np.errstate(invalid="ignore", divide="ignore"):
            alpha = np.where(n > 0, self.sum_image / self.sum_light, np.nan)
            lam = np.where(n > 0, self.sum_shift / n, np.nan)
            psi = np.where(n > 0, self.sum_spread / n, np.nan)
        return Characterisation(renderer, dict(options), design, self.classes, self.edges,
                                alpha, lam, psi, self.n.astype(np.int64), np.array(self.profiles),
                                np.array(self.profile_counts).astype(np.int64),
                                self.hist_global.astype(np.int64), self.hist_local.astype(np.int64),
                                dict(settings), np.array(self.blocks), np.array(self.phi_sums),
                                np.array(self.phi_counts).astype(np.int64))
