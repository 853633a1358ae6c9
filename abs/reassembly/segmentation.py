"""Segment photographs into material labels: edge detection plus watershed per photograph, then
one set of labels shared by all photographs (micropolygon labelling, docs/reassembly.md).

A photograph is first cut into regions: Canny edges on each channel of the gamma-encoded image, the connected
pieces of what is not an edge become the watershed's seeds, and the watershed over the colour
gradient (Sobel) grows them until they meet. Regions of different photographs do not correspond,
so each region is then given one of ``n_labels`` labels by k-means over the regions' mean colours
of all photographs together (in log linear RGB, where shading scales every channel alike and so
moves a colour along one direction only).

Label images: ``int32`` of the photograph's size, ``0`` unknown (watershed lines, masked-out
and black pixels), ``1..n_labels`` the labels, ordered by the label's mean
luminance (darkest first) so that the same photographs give the same numbering.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.cluster.vq import kmeans2
from skimage.filters import sobel
from skimage.segmentation import watershed

from abs.colour.srgb import linear_to_srgb, luminance
from abs.errors import InputError

__all__ = ["Segmentation", "segment_photograph", "label_regions"]

_EPS = 1e-3  # linear radiance added before the log: keeps black pixels finite


@dataclass(frozen=True)
class Segmentation:
    """The watershed regions of one photograph.

    Attributes
    ----------
    regions : (H, W) int32
        Region id per pixel, ``0`` on watershed lines and masked-out pixels.
    colours : (n, 3) float64
        Mean log linear RGB of region ``i + 1``.
    areas : (n,) int
        Pixels of each region.
    """

    regions: np.ndarray
    colours: np.ndarray
    areas: np.ndarray


def segment_photograph(image: np.ndarray, mask: np.ndarray | None = None, sigma_px: float = 1.0, median: bool = True,
                       canny: tuple[float, float] = (20.0, 50.0), min_area_px: int = 20,
                       source: object = None) -> Segmentation:
    """Cut a photograph into regions by edge detection plus watershed.

    Parameters
    ----------
    image : (H, W, 3) float array
        Linear RGB (docs/conventions.md).
    mask : (H, W) bool array, optional
        Pixels to segment (``False``: unknown, e.g. an object standing in front of the mesh);
        black pixels (no light recorded) are left out too.
    sigma_px : float
        Gaussian blur before the edges, pixels (rendering and sensor noise would otherwise cut
        the image into specks).
    median : bool
        A 5x5 median filter before the blur.
    canny : (low, high)
        Canny hysteresis thresholds on each channel of the 8-bit gamma-encoded image (levels).
    min_area_px : int
        Seeds (pieces between edges) smaller than this are dropped: their pixels are claimed by
        the neighbouring regions' watershed.
    source : path or str, optional
        Named in errors.

    Returns
    -------
    Segmentation

    Raises
    ------
    InputError
        Not an ``(H, W, 3)`` image, a mask of another size, or no region at all (a blank or
        fully masked photograph: an empty segmentation).
    """
    image = np.asarray(image, dtype=np.float32)
    if image.ndim != 3 or image.shape[2] < 3:
        raise InputError(source, "", f"expected an (H, W, 3) colour photograph, got shape {list(image.shape)}")
    image = np.nan_to_num(image[..., :3], nan=0.0, posinf=0.0, neginf=0.0).clip(0, None)
    if mask is None:
        mask = np.ones(image.shape[:2], dtype=bool)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != image.shape[:2]:
        raise InputError(source, "mask", f"is {mask.shape[1]}x{mask.shape[0]}, the photograph "
                                         f"{image.shape[1]}x{image.shape[0]}")
    # a median first: rendering noise and hot pixels are outliers a Gaussian only spreads out
    smooth = cv2.medianBlur(np.ascontiguousarray(image), 5) if median else image
    smooth = cv2.GaussianBlur(smooth, (0, 0), sigma_px) if sigma_px > 0 else smooth
    # a pixel that recorded no light at all (unexposed, outside the lens's circle) says nothing
    # about the material there
    mask = mask & (smooth.max(axis=2) > 0)
    # Edges are found on the display encoding, where a step in a dark part of the scene is as
    # visible as one in a bright part (on linear values Canny sees only the bright ones).
    scale = max(float(np.percentile(smooth[mask], 99.5)) if mask.any() else 0.0, 1e-12)
    encoded = linear_to_srgb(np.clip(smooth / scale, 0, 1))
    # per channel: two materials of one brightness but different hues (green and blue) have no
    # edge in a grey image
    channels = np.clip(encoded * 255, 0, 255).astype(np.uint8)
    edges = np.any([cv2.Canny(np.ascontiguousarray(channels[..., c]), *canny) > 0 for c in range(3)], axis=0)
    edges = cv2.dilate(edges.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    count, seeds = cv2.connectedComponents((~edges & mask).astype(np.uint8), connectivity=4)
    sizes = np.bincount(seeds.ravel(), minlength=count)
    sizes[0] = 0
    keep = sizes >= min_area_px
    relabel = np.zeros(count, dtype=np.int32)
    relabel[keep] = np.arange(1, int(keep.sum()) + 1)
    seeds = relabel[seeds]
    if seeds.max() == 0:
        raise InputError(source, "", "empty segmentation: no region of at least "
                                     f"{min_area_px} pixels between edges (blank or masked-out photograph?)")
    logs = np.log(smooth + _EPS)
    elevation = np.max([sobel(encoded[..., c]) for c in range(3)], axis=0)
    regions = watershed(elevation, seeds, mask=mask, watershed_line=True).astype(np.int32)
    n = int(regions.max())
    areas = np.bincount(regions.ravel(), minlength=n + 1)[1:]
    colours = np.stack([np.bincount(regions.ravel(), weights=logs[..., c].ravel(), minlength=n + 1)[1:]
                        for c in range(3)], axis=1) / np.maximum(areas, 1)[:, None]
    return Segmentation(regions, colours, areas)


def label_regions(segmentations: list[Segmentation], n_labels: int, seed: int = 0,
                  samples: int = 20000) -> tuple[list[np.ndarray], np.ndarray]:
    """Give every region of every photograph one of ``n_labels`` shared labels.

    K-means over the regions' mean log colours, each region weighted by its area (regions are
    drawn in proportion to their pixels), so that the many small regions a textured or noisy
    patch breaks into do not outvote the large ones.

    Parameters
    ----------
    segmentations : list of Segmentation
        One per photograph.
    n_labels : int
        Number of materials to tell apart, >= 1.
    seed : int
        Seed of the k-means initialisation and of the area-weighted draw.
    samples : int
        Regions drawn (with repetition, by area) for k-means.

    Returns
    -------
    label_images : list of (H, W) int32
        ``0`` unknown, ``1..n_labels`` labels, ordered by mean luminance (darkest first).
    colours : (n_labels, 3) float64
        Each label's mean linear RGB in the photographs (not a reflectance: it includes the light).
    """
    if n_labels < 1:
        raise InputError(None, "--labels", f"expected at least 1 label, got {n_labels}")
    feats = np.concatenate([s.colours for s in segmentations])
    weights = np.concatenate([s.areas for s in segmentations]).astype(np.float64)
    if len(feats) < n_labels:
        raise InputError(None, "--labels", f"{n_labels} labels asked for, but the photographs hold "
                                           f"only {len(feats)} regions")
    rng = np.random.default_rng(seed)
    drawn = feats[rng.choice(len(feats), size=samples, p=weights / weights.sum())]
    centres, _ = kmeans2(drawn, n_labels, minit="++", seed=seed)
    assign = np.argmin(((feats[:, None] - centres[None]) ** 2).sum(axis=2), axis=1)
    # luminance order: a numbering that does not depend on
    # which centre k-means happened to start from
    linear = np.exp(centres) - _EPS
    order = np.argsort(luminance(linear))
    rank = np.empty(n_labels, dtype=np.int32)
    rank[order] = np.arange(1, n_labels + 1)
    images, start = [], 0
    for s in segmentations:
        lut = np.zeros(len(s.colours) + 1, dtype=np.int32)
        lut[1:] = rank[assign[start:start + len(s.colours)]]
        start += len(s.colours)
        images.append(lut[s.regions])
    return images, linear[order]
