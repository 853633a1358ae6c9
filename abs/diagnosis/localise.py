"""Where does the residual of a fitted model concentrate?

The residual map of a view is the per-pixel squared RGB error of the fitted rendering against the
photograph. Regions are connected areas where the (lightly smoothed) map exceeds three times its
median (the median pixel is mostly noise when the misfit is concentrated); each reports its
bounding box, its share of the squared residual summed over all views, and *where* it is: the
objects and materials seen in it (primary rays through the pixel centres intersected with the
Mitsuba scene; ``environment`` where they escape) and its position in the image (centre, middle,
corners), since some missing effects are tied to materials and others to the sensor.

The label also says what kind of image feature the residual sits on, since several missing
effects have a signature there:

- ``edges of <object> (as if moved by dx/dy px)``: at least half the region's squared residual
  is what moving the fitted rendering by one displacement leaves (least squares of the residual
  on the rendering's x and y derivatives, all channels, unblurred and blurred by 1 and 2 pixels
  so that shifts of a few pixels stay linear): the error lines along the checkerboard's and the
  outlines' edges that a misaligned camera makes.
- ``highlights``: at least half the region's squared residual lies on pixels over three times
  the view's median luminance (and in its top 10 %) in the rendering or the photograph, where a
  misoriented environment map moves bright reflections and refractions.
- ``seen through <object>``: pixels whose primary ray hits a transmissive material, so what they
  show is refracted (wrong glass geometry, absorption, roughness).
- ``whole image: colour shift``: not a region of the median threshold (a shift over the whole
  image raises the median with it) but one per view when the mean residual explains most of the
  view's squared residual and differs between channels, as a colour-calibration error makes.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.camera import Camera

__all__ = ["Region", "ResidualMap", "pixel_objects", "residual_maps", "find_regions", "breakdown",
           "describe", "shift_fit", "highlight_pixels"]

ENVIRONMENT = "environment"
MAX_REGIONS = 6
MIN_SHARE = 0.02       # smaller regions are not worth naming
LABEL_FRACTION = 0.2   # an object is named if it covers this fraction of a region
EDGE_SHARE = 0.5       # a moved image explains this share of a region's squared residual: edges
HIGHLIGHT_SHARE = 0.5  # this share of a region's squared residual lies on highlights
OFFSET_SHARE = 0.5     # the mean residual explains this share of a view's: a whole-image shift


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
    rendering : ndarray, shape (H, W, 3), optional
        The fitted rendering (linear RGB), for the edge and highlight labels.
    transmissive : tuple of bool, optional
        Per entry of ``names``: whether its material transmits light (glass).
    """

    view: str
    holdout: bool
    residual: np.ndarray
    mask: np.ndarray
    objects: np.ndarray
    names: tuple[str, ...]
    rendering: np.ndarray | None = None
    transmissive: tuple[bool, ...] = ()

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


def pixel_objects(compiled, camera: Camera) -> tuple[np.ndarray, tuple[str, ...], tuple[bool, ...]]:
    """Which object each pixel centre sees: an index map (-1: environment), the labels and
    whether each label's material is transmissive."""
    w, h = camera.width, camera.height
    idx = dr.arange(mi.UInt32, w * h)
    origin, direction = camera.rays(mi.Float(idx % w), mi.Float(idx // w))
    si = compiled.mitsuba_scene.ray_intersect(mi.Ray3f(origin, direction))
    valid = np.array(si.is_valid(), bool)
    labels = np.full(w * h, -1, np.int32)
    names, transmissive = [], []
    # Shape ids are object names unless a material shares the name (CompiledScene.shape_ids).
    objects = {compiled.shape_ids[o.name]: o for o in compiled.scene.objects}
    for k, shape in enumerate(compiled.mitsuba_scene.shapes()):
        hit = np.array(si.shape == mi.ShapePtr(shape), bool) & valid
        labels[hit] = k
        obj = objects.get(shape.id())
        names.append(f"{shape.id()} (?)" if obj is None else f"{obj.name} ({obj.material})")
        transmissive.append(obj is not None and compiled.scene.materials[obj.material].transmissive)
    return labels.reshape(h, w), tuple(names), tuple(transmissive)


def residual_maps(compiled, views, cameras: dict[str, Camera]) -> list[ResidualMap]:
    """Residual maps of fitted renderings (``abs.fitting.fit.ViewRenderings``)."""
    maps = []
    for v in views:
        objects, names, transmissive = pixel_objects(compiled, cameras[v.name])
        maps.append(ResidualMap(v.name, v.holdout, v.after - v.photograph, v.mask, objects, names,
                                v.after, transmissive))
    return maps


def _position(cx: float, cy: float, w: int, h: int) -> str:
    r = np.hypot((cx - (w - 1) / 2) / (w / 2), (cy - (h - 1) / 2) / (h / 2)) / np.sqrt(2)
    return "image centre" if r < 0.3 else ("image corners" if r > 0.65 else "mid-image")


def _object_fractions(m: ResidualMap, pixels: np.ndarray) -> dict[str, float]:
    ids, counts = np.unique(m.objects[pixels], return_counts=True)
    total = counts.sum()
    return {(ENVIRONMENT if i < 0 else m.names[i]): float(c / total)
            for i, c in sorted(zip(ids, counts), key=lambda t: -t[1])}


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ np.array([0.2126, 0.7152, 0.0722])  # Rec. 709, the rendering's primaries


#: Scales (Gaussian sigma, pixels) at which a residual is compared with a moved rendering: a
#: displacement is linear in the rendering's derivative only over about the width of its edges,
#: so a shift of a few pixels (a misalignment at a higher resolution) is seen on blurred images.
SHIFT_SCALES_PX = (0.0, 1.0, 2.0)


def _gradients(m: ResidualMap) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None:
    """Per scale of :data:`SHIFT_SCALES_PX`: the blurred rendering's derivatives along x and y per
    channel (central differences, per pixel) and the residual blurred alike; ``None`` without a
    rendering."""
    if m.rendering is None:
        return None
    out = []
    for sigma in SHIFT_SCALES_PX:
        rendering = np.asarray(m.rendering, np.float64)
        residual = np.asarray(m.residual, np.float64) * m.mask[..., None]
        if sigma > 0:
            rendering = cv2.GaussianBlur(rendering, (0, 0), sigma)
            residual = cv2.GaussianBlur(residual, (0, 0), sigma)
        gy, gx = np.gradient(rendering, axis=(0, 1))
        out.append((gx, gy, residual))
    return out


def shift_fit(m: ResidualMap, pixels: np.ndarray, gradients=None) -> tuple[float, np.ndarray]:
    """How well the residual in ``pixels`` is the rendering moved by one displacement: least
    squares of ``residual ~ gx dx + gy dy`` (all channels, one ``(dx, dy)``), at each scale of
    :data:`SHIFT_SCALES_PX` (rendering and residual blurred alike). Returns the best share of
    the pixels' squared (blurred) residual it explains (R^2) and its ``(dx, dy)`` in pixels: to
    first order the photograph shows the rendering's content moved by ``(dx, dy)``
    (``P(u) = R(u - d)``, so ``R - P ~ grad R . d``)."""
    gradients = _gradients(m) if gradients is None else gradients
    best = (0.0, np.zeros(2))
    for gx, gy, residual in gradients or []:
        A = np.stack([gx[pixels].ravel(), gy[pixels].ravel()], axis=1)
        r = residual[pixels].ravel()
        total = float(r @ r)
        if total <= 0.0 or not np.any(A):
            continue
        d, *_ = np.linalg.lstsq(A, r, rcond=None)
        rest = r - A @ d
        explained = 1.0 - float(rest @ rest) / total
        if explained > best[0]:
            best = (explained, d)
    return best


def highlight_pixels(m: ResidualMap) -> np.ndarray | None:
    """Pixels over three times the view's median luminance and in its top 10 %, in the fitted
    rendering or in the photograph (a misplaced highlight errs where either has it); ``None``
    without a rendering."""
    if m.rendering is None or not m.mask.any():
        return None
    out = np.zeros(m.mask.shape, bool)
    for image in (m.rendering, m.rendering - m.residual):
        lum = _luminance(np.asarray(image, np.float64))
        inside = lum[m.mask]
        out |= (lum > max(3.0 * float(np.median(inside)), float(np.quantile(inside, 0.9)))) & m.mask
    return out


def describe(m: ResidualMap, pixels: np.ndarray, gradients=None, highlights=None) -> str:
    """The ``where`` label of the pixels ``pixels`` of view ``m``: objects (transmissive ones as
    ``seen through``), the feature the residual concentrates on (edges, highlights; module
    docstring), and the position."""
    fractions = _object_fractions(m, pixels)
    see_through = {name for name, t in zip(m.names, m.transmissive) if t}
    named = [k for k, f in fractions.items() if f >= LABEL_FRACTION] or list(fractions)[:1]
    parts = [f"seen through {k}" if k in see_through else k for k in named]
    explained, d = shift_fit(m, pixels, gradients)
    if explained >= EDGE_SHARE:
        parts = [f"edges of {named[0]} (as if moved by {d[0]:+.2g}/{d[1]:+.2g} px)"] + parts[1:]
    highlights = highlight_pixels(m) if highlights is None else highlights
    if highlights is not None:
        e2 = m.squared * pixels
        if float(e2[highlights].sum()) >= HIGHLIGHT_SHARE * (float(e2.sum()) or 1.0):
            parts.append("highlights")
    h, w = pixels.shape
    y, x = np.nonzero(pixels)
    return " / ".join(parts) + "; " + _position(float(x.mean()), float(y.mean()), w, h)


def _colour_shift(m: ResidualMap, total: float) -> Region | None:
    """A whole-view region when the view's mean residual explains most of its squared residual
    and differs between channels (module docstring); ``None`` otherwise."""
    if not m.mask.any():
        return None
    r = m.residual[m.mask].astype(np.float64)
    mean = r.mean(axis=0)
    explained = float(np.sum(mean ** 2)) * r.shape[0]
    if explained < OFFSET_SHARE * float(np.sum(r ** 2)) or np.ptp(mean) < 0.5 * np.max(np.abs(mean)):
        return None
    h, w = m.mask.shape
    channel = "RGB"[int(np.argmax(mean))]
    where = (f"whole image: colour shift (rendering too {'bright' if mean.max() > 0 else 'dark'} "
             f"most in {channel}: mean residual {mean[0]:+.3g}/{mean[1]:+.3g}/{mean[2]:+.3g})")
    return Region(m.view, (0, 0, w, h), explained / total, where, _object_fractions(m, m.mask),
                  mean.tolist())


def find_regions(maps: list[ResidualMap]) -> list[Region]:
    """The largest connected regions of residual, over all views, by share (at most six), and a
    whole-view colour-shift region for each view that has one."""
    total = sum(float(m.squared.sum()) for m in maps) or 1.0
    regions = []
    for m in maps:
        shift = _colour_shift(m, total)
        if shift is not None:
            regions.append(shift)
        gradients, highlights = _gradients(m), highlight_pixels(m)
        e2 = m.squared
        h, w = e2.shape
        size = max(3, (min(h, w) // 16) | 1)
        smooth = cv2.blur(e2.astype(np.float32), (size, size))
        level = 3.0 * float(np.median(smooth[m.mask])) if m.mask.any() else 0.0
        hot = ((smooth > level) & m.mask).astype(np.uint8)
        n, comp, stats, _ = cv2.connectedComponentsWithStats(hot, connectivity=8)
        for i in range(1, n):
            pixels = comp == i
            share = float(e2[pixels].sum()) / total
            if share < MIN_SHARE:
                continue
            x, y, bw, bh = (int(s) for s in stats[i, :4])
            regions.append(Region(m.view, (x, y, x + bw, y + bh), share, describe(m, pixels, gradients, highlights),
                                  _object_fractions(m, pixels), m.residual[pixels].mean(axis=0).tolist()))
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
