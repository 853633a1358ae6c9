"""Where does the residual of a fitted model concentrate?

The residual map of a view is the per-pixel squared RGB error of the fitted rendering against the
photograph. Regions are connected areas where the (lightly smoothed) map exceeds three times its
median (the median pixel is mostly noise when the misfit is concentrated); each reports its
bounding box, its share of the squared residual summed over all views, and *where* it is: the
objects and materials seen in it (primary rays through the pixel centres intersected with the
Mitsuba scene; ``environment`` where they escape) and its position in the image (centre, middle,
corners), since some missing effects are tied to materials and others to the sensor.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.camera import Camera

__all__ = ["Region", "ResidualMap", "pixel_objects", "residual_maps", "find_regions", "breakdown"]

ENVIRONMENT = "environment"
MAX_REGIONS = 6
MIN_SHARE = 0.02       # smaller regions are not worth naming
LABEL_FRACTION = 0.2   # an object is named if it covers this fraction of a region


@dataclass(frozen=True)
class ResidualMap:
    """One view's residual at full resolution.

    Attributes
    ----------
    view : str
    holdout : bool
    residual : ndarray, shape (H, W, 3)
        Rendering minus photograph (linear RGB).
    mask : ndarray of bool, shape (H, W)
    objects : ndarray of int, shape (H, W)
        Index into ``names`` of the object seen through each pixel centre; -1: the environment.
    names : tuple of str
        ``object (material)`` labels.
    """

    view: str
    holdout: bool
    residual: np.ndarray
    mask: np.ndarray
    objects: np.ndarray
    names: tuple[str, ...]

    @property
    def squared(self) -> np.ndarray:
        """Squared RGB error per pixel (zero outside the mask)."""
        return np.sum(np.square(self.residual), axis=-1) * self.mask


@dataclass(frozen=True)
class Region:
    """A connected area of large residual in one view.

    Attributes
    ----------
    view : str
    bbox : (x0, y0, x1, y1)
        Pixel bounds at the photograph's resolution, ``x1``/``y1`` exclusive.
    share_of_residual : float
        Fraction of the squared residual of all views inside the region.
    where : str
        Objects (materials) seen in it and its position in the image.
    objects : dict
        Fraction of the region's pixels showing each object (``environment`` for escaped rays).
    mean_residual : list of float
        Mean rendering-minus-photograph per R, G, B (positive: the rendering is too bright).
    """

    view: str
    bbox: tuple[int, int, int, int]
    share_of_residual: float
    where: str
    objects: dict
    mean_residual: list

    def to_json(self) -> dict:
        return {"view": self.view, "bbox": list(self.bbox),
                "share_of_residual": round(self.share_of_residual, 4), "where": self.where,
                "objects": {k: round(v, 3) for k, v in self.objects.items()},
                "mean_residual": [round(x, 5) for x in self.mean_residual]}


def pixel_objects(compiled, camera: Camera) -> tuple[np.ndarray, tuple[str, ...]]:
    """Which object each pixel centre sees: an index map (-1: environment) and the labels."""
    w, h = camera.width, camera.height
    idx = dr.arange(mi.UInt32, w * h)
    origin, direction = camera.rays(mi.Float(idx % w), mi.Float(idx // w))
    si = compiled.mitsuba_scene.ray_intersect(mi.Ray3f(origin, direction))
    valid = np.array(si.is_valid(), bool)
    labels = np.full(w * h, -1, np.int32)
    names = []
    # Shape ids are object names unless a material shares the name (CompiledScene.shape_ids).
    objects = {compiled.shape_ids[o.name]: o for o in compiled.scene.objects}
    for k, shape in enumerate(compiled.mitsuba_scene.shapes()):
        hit = np.array(si.shape == mi.ShapePtr(shape), bool) & valid
        labels[hit] = k
        obj = objects.get(shape.id())
        names.append(f"{shape.id()} (?)" if obj is None else f"{obj.name} ({obj.material})")
    return labels.reshape(h, w), tuple(names)


def residual_maps(compiled, views, cameras: dict[str, Camera]) -> list[ResidualMap]:
    """Residual maps of fitted renderings (``abs.fitting.fit.ViewRenderings``)."""
    maps = []
    for v in views:
        objects, names = pixel_objects(compiled, cameras[v.name])
        maps.append(ResidualMap(v.name, v.holdout, v.after - v.photograph, v.mask, objects, names))
    return maps


def _position(cx: float, cy: float, w: int, h: int) -> str:
    r = np.hypot((cx - (w - 1) / 2) / (w / 2), (cy - (h - 1) / 2) / (h / 2)) / np.sqrt(2)
    return "image centre" if r < 0.3 else ("image corners" if r > 0.65 else "mid-image")


def _object_fractions(m: ResidualMap, pixels: np.ndarray) -> dict[str, float]:
    ids, counts = np.unique(m.objects[pixels], return_counts=True)
    total = counts.sum()
    return {(ENVIRONMENT if i < 0 else m.names[i]): float(c / total)
            for i, c in sorted(zip(ids, counts), key=lambda t: -t[1])}


def find_regions(maps: list[ResidualMap]) -> list[Region]:
    """The largest connected regions of residual, over all views, by share (at most six)."""
    total = sum(float(m.squared.sum()) for m in maps) or 1.0
    regions = []
    for m in maps:
        e2 = m.squared
        h, w = e2.shape
        size = max(3, (min(h, w) // 16) | 1)
        smooth = cv2.blur(e2.astype(np.float32), (size, size))
        level = 3.0 * float(np.median(smooth[m.mask])) if m.mask.any() else 0.0
        hot = ((smooth > level) & m.mask).astype(np.uint8)
        n, comp, stats, centroids = cv2.connectedComponentsWithStats(hot, connectivity=8)
        for i in range(1, n):
            pixels = comp == i
            share = float(e2[pixels].sum()) / total
            if share < MIN_SHARE:
                continue
            x, y, bw, bh = (int(s) for s in stats[i, :4])
            fractions = _object_fractions(m, pixels)
            named = [k for k, f in fractions.items() if f >= LABEL_FRACTION] or list(fractions)[:1]
            where = " / ".join(named) + "; " + _position(*centroids[i], w, h)
            regions.append(Region(m.view, (x, y, x + bw, y + bh), share, where, fractions,
                                  m.residual[pixels].mean(axis=0).tolist()))
    return sorted(regions, key=lambda r: -r.share_of_residual)[:MAX_REGIONS]


def breakdown(maps: list[ResidualMap]) -> dict:
    """Shares of the squared residual by object, by distance from the image centre (four rings
    of equal width in normalised radius), and by colour channel, with the mean signed residual
    per channel: the summary a reader uses to guess the missing physics."""
    total = sum(float(m.squared.sum()) for m in maps) or 1.0
    objects: dict[str, float] = {}
    rings = np.zeros(4)
    channels = np.zeros(3)
    signed, count = np.zeros(3), 0
    for m in maps:
        e2 = m.squared
        h, w = e2.shape
        for i in np.unique(m.objects):
            key = ENVIRONMENT if i < 0 else m.names[i]
            objects[key] = objects.get(key, 0.0) + float(e2[m.objects == i].sum()) / total
        y, x = np.mgrid[0:h, 0:w]
        r = np.hypot((x - (w - 1) / 2) / (w / 2), (y - (h - 1) / 2) / (h / 2)) / np.sqrt(2)
        ring = np.minimum((r * 4).astype(int), 3)
        rings += np.bincount(ring[m.mask], weights=e2[m.mask], minlength=4) / total
        channels += np.sum(np.square(m.residual[m.mask]), axis=0) / total
        signed += m.residual[m.mask].sum(axis=0)
        count += int(m.mask.sum())
    return {"objects": dict(sorted(objects.items(), key=lambda t: -t[1])),
            "radius_rings": rings.tolist(), "channels": channels.tolist(),
            "mean_residual": (signed / max(count, 1)).tolist()}
