"""Circular markers in a photograph: OpenCV's Hough transform over an image pyramid.

``cv2.HOUGH_GRADIENT_ALT`` finds circles whose radius lies in the band it is given, and is both
slow and unreliable when that band is wide (measured: a 640x480 image with radii 2 to 160 px took
0.5 s and missed the 5 and 6 px markers; 2560x1920 took minutes). So the image is resampled
by factors 2, 1, 1/2, 1/4, ... and each level searched for radii of 8 to 20 px *at that
level*: 4 to 10 px in the image, then 8 to 20, 16 to 40, ... The same marker at any image size
falls in some level's band ("works at any size"); the bands overlap, so that a radius at a band's
edge is not lost, and detections of one marker at two levels are merged. Below about 4 px nothing
is found (measured: 4.2 px found, 3.9 px not). Two markers whose discs touch in an image are one
blob to the transform, and at most one of them is found.

The Hough centres lie on a half-pixel grid of their level (2 px at the level 1/4); each is
refined on the full image, first by the centroid of the marker's darkness (a coverage weight
between the median inside the disc and the median of a ring around it) and the radius of its
area, then by a circle fitted to the marker's edge with outlying edge points dropped (a marker on
glass has its own refracted image beside it, which pulls a centroid but only a minority of the
edge). Pixel coordinates follow docs/conventions.md: ``(0, 0)`` is the centre of
the top-left pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Circles", "detect_circles", "to_grey"]

_BAND = (8, 20)  # radii searched at each pyramid level, px of that level (overlapping octaves)
_MIN_LEVEL_SIZE = 64  # smallest side of a level worth searching, px


@dataclass(frozen=True)
class Circles:
    """Circles found in one image.

    Attributes
    ----------
    centres_px : np.ndarray
        ``(n, 2)`` centres ``(u, v)``, pixels.
    radii_px : np.ndarray
        ``(n,)`` radii, pixels.
    contrast : np.ndarray
        ``(n,)`` ``(ring - disc) / ring`` (linear levels; negative for a light disc found with
        ``polarity="light"``).
    """

    centres_px: np.ndarray
    radii_px: np.ndarray
    contrast: np.ndarray

    def __len__(self) -> int:
        return len(self.radii_px)


def to_grey(image: np.ndarray) -> np.ndarray:
    """``image`` (``(h, w)`` or ``(h, w, c)``, any dtype) as grey float64 in [0, 1]: divided by
    its 99.5th percentile, so that the ground is near 1 and black stays 0.

    Not stretched between low and high percentiles: markers fill a tiny share of a photograph,
    so a low percentile lands on the ground's texture, and stretching from there made texture
    as contrasted as a marker (measured: Hough circles in the texture passed the contrast test).
    """
    grey = np.asarray(image, dtype=np.float64)
    if grey.ndim == 3:
        grey = grey[..., :3].mean(axis=2)
    if grey.ndim != 2:
        raise ValueError(f"expected an (h, w) or (h, w, c) image, got shape {np.shape(image)}")
    top = np.percentile(grey, 99.5)
    if not top > 0:
        return np.zeros_like(grey)
    return np.clip(grey / top, 0.0, 1.0)


def _levels(shape: tuple[int, int], r_min: float, r_max: float) -> list[float]:
    """Resampling factors whose radius band ``_BAND / s`` overlaps ``[r_min, r_max]``."""
    out, s = [], 2.0
    while min(shape) * s >= _MIN_LEVEL_SIZE:
        lo, hi = _BAND[0] / s, _BAND[1] / s
        if hi >= r_min and lo <= r_max:
            out.append(s)
        if lo > r_max:
            break
        s /= 2
    return out


def _hough(grey8: np.ndarray, s: float) -> np.ndarray:
    """``(k, 3)`` circles ``(u, v, r)`` in image pixels found at resampling factor ``s``."""
    interp = cv2.INTER_LINEAR if s > 1 else cv2.INTER_AREA
    level = grey8 if s == 1 else cv2.resize(grey8, None, fx=s, fy=s, interpolation=interp)
    # sigma 1.2 px of the level, and at least one image pixel: enough to keep noise from the
    # edge map (at 0.8 px the transform took minutes on a noisy 2560x1920 image, and 20 s on the
    # doubled level of a noisy rendering at 1.2 px), small against a marker of 8 px.
    level = cv2.GaussianBlur(level, (0, 0), max(1.2, s))
    # param1: Canny high threshold on the 8-bit image; param2: circle "perfectness" (1 =
    # perfect); 0.6 keeps small, pixelated discs that 0.8 lost.
    found = cv2.HoughCircles(level, cv2.HOUGH_GRADIENT_ALT, dp=1, minDist=_BAND[0], param1=200,
                             param2=0.6, minRadius=_BAND[0], maxRadius=_BAND[1])
    if found is None:
        return np.zeros((0, 3))
    c = found.reshape(-1, 3).astype(np.float64)
    # pixel-centre convention: the level's pixel x covers image [(x - 0.5) / s, (x + 0.5) / s]
    return np.column_stack([(c[:, :2] + 0.5) / s - 0.5, c[:, 2] / s])


def _refine(grey: np.ndarray, u: float, v: float, r: float) -> tuple[float, float, float, float]:
    """Centroid and area radius of the marker's darkness near ``(u, v, r)``, and its contrast
    ``(ring - disc) / ring``; the contrast is 0 when the ring is not clean.

    ``grey`` is linear (a partly covered pixel is the linear mix of marker and ground). A ring
    (1.5 to 2 r) of which more than 15 % is darker than a quarter of the way from the disc to the
    ring's median is not clean (a noisy rendering of a dark ground passes; at half-way and 10 %
    it did not): the
    disc touches another dark thing (another marker, the dark rim of a glass silhouette), which
    would pull the centroid (measured: 5 px on a rendered marker at the sphere's rim).
    """
    h, w = grey.shape
    half = int(np.ceil(2.2 * r)) + 2
    x0, x1 = max(int(u) - half, 0), min(int(u) + half + 1, w)
    y0, y1 = max(int(v) - half, 0), min(int(v) + half + 1, h)
    patch = grey[y0:y1, x0:x1]
    yy, xx = np.mgrid[y0:y1, x0:x1]
    contrast = 0.0
    for _ in range(2):  # the second pass starts from the refined centre
        d = np.hypot(xx - u, yy - v)
        disc, ring = patch[d <= 0.5 * r], patch[(d >= 1.5 * r) & (d <= 2.0 * r)]
        if disc.size == 0 or ring.size == 0:
            return u, v, r, 0.0
        inside, outside = np.median(disc), np.median(ring)
        step = float(outside - inside)
        if step <= 0 or outside <= 0:
            return u, v, r, 0.0
        if np.mean(ring < inside + 0.25 * step) > 0.15:
            return u, v, r, 0.0
        contrast = step / float(outside)
        # coverage 0.25 -> 0, 0.75 -> 1, linear between: symmetric about half coverage, so an
        # edge keeps its area, while ground texture darker than the ring by less than a quarter
        # of the step (measured: it pulled a 60 px centre by 1 px) adds nothing.
        weight = np.clip(2.0 * (outside - patch) / step - 0.5, 0.0, 1.0) * (d <= 1.4 * r)
        total = weight.sum()
        if total <= 0:
            return u, v, r, 0.0
        u, v = float((weight * xx).sum() / total), float((weight * yy).sum() / total)
        r = float(np.sqrt(total / np.pi))
    return u, v, r, contrast


def _edge_circle(grey: np.ndarray, u: float, v: float, r: float, contrast: float,
                 rays: int = 120) -> tuple[float, float, float]:
    """Circle through the marker's edge, robust to a dark blob beside it.

    A marker glued on glass is seen again, refracted, through the glass right beside it: its dark
    blob grows on one side, and the centroid moves towards it (measured on abs renderings: 1 to
    3 px at a radius of 12 px). Here the edge is found on ``rays`` rays from the centroid (where
    the linear level first rises above half-way from the disc to the ring), a circle is fitted to
    the edge points (Kasa), and points further than 3 robust standard deviations (at least
    0.3 px) from it are dropped and the circle refitted: the edge of the extra blob is a minority
    of the rays and leaves. Falls back to ``(u, v, r)`` when fewer than half the rays keep an edge.
    """
    from scipy.ndimage import map_coordinates

    step = 0.1  # px along a ray
    angles = np.linspace(0.0, 2 * np.pi, rays, endpoint=False)
    radii = np.arange(0.3 * r, 2.0 * r, step)
    xs = u + np.cos(angles)[:, None] * radii[None]
    ys = v + np.sin(angles)[:, None] * radii[None]
    values = map_coordinates(grey, [ys.ravel(), xs.ravel()], order=1, mode="nearest").reshape(xs.shape)
    # the levels of _refine: the ring's median, and the disc's from the contrast
    outside = np.median(values[:, radii >= 1.5 * r])
    inside = outside * (1.0 - contrast)
    mid = inside + 0.5 * (outside - inside)
    above = values > mid
    first = np.argmax(above, axis=1)
    ok = above.any(axis=1) & (first > 0)
    if ok.sum() < rays // 2:
        return u, v, r
    i, a = first[ok], angles[ok]
    before, after = values[ok, i - 1], values[ok, i]
    edge = radii[i - 1] + (mid - before) / (after - before) * step
    points = np.column_stack([u + np.cos(a) * edge, v + np.sin(a) * edge])
    keep = np.ones(len(points), bool)
    for _ in range(6):
        A = np.column_stack([2 * points[keep], np.ones(keep.sum())])
        sol = np.linalg.lstsq(A, (points[keep] ** 2).sum(axis=1), rcond=None)[0]
        centre = sol[:2]
        radius = float(np.sqrt(max(sol[2] + centre @ centre, 0.0)))
        residual = np.abs(np.linalg.norm(points - centre, axis=1) - radius)
        keep = residual < max(0.3, 3 * 1.4826 * np.median(residual[keep]))
        if keep.sum() < rays // 2:
            return u, v, r
    return float(centre[0]), float(centre[1]), radius


def detect_circles(image: np.ndarray, *, radius_px: tuple[float, float | None] = (4.0, None),
                   polarity: str = "dark", min_contrast: float = 0.5) -> Circles:
    """Circular markers of any size in ``image``.

    Parameters
    ----------
    image : np.ndarray
        ``(h, w)`` or ``(h, w, c)`` image, any dtype (linear or not: only edges are used).
    radius_px : (float, float or None)
        Accepted radii, pixels. The lower end is at least 4 px (the finest pyramid level, the
        image doubled, finds 4 px); ``None`` as the upper end means a quarter of the image's
        smaller side.
    polarity : {"dark", "light", "any"}
        Keep dark discs on a lighter ground (markers of a dark material), light ones, or both.
    min_contrast : float
        Least ``(ring - disc) / ring`` (linear levels, the ring 1.5 to 2 radii around the
        disc): a dark marker reflects a few percent of what the ground does, so its contrast is
        near 1; rejects circles the Hough transform finds in texture. Detections whose ring is
        not clean (touching another dark thing) are rejected too.

    Returns
    -------
    Circles
        Sorted by ``v`` then ``u``.
    """
    if polarity not in ("dark", "light", "any"):
        raise ValueError(f"polarity must be 'dark', 'light' or 'any', got {polarity!r}")
    grey = to_grey(image)
    r_min = max(float(radius_px[0]), 4.0)
    r_max = float(radius_px[1]) if radius_px[1] is not None else min(grey.shape) / 4
    # edges are found on a gamma-encoded image (as sRGB, 1/2.2), so that a marker on a dark part
    # of the scene (the glass, measured on a rendering) still has edges above the Canny threshold;
    # the centres are refined on the linear image
    grey8 = np.round(grey ** (1 / 2.2) * 255).astype(np.uint8)
    found = [_hough(grey8, s) for s in _levels(grey.shape, r_min, r_max)]
    candidates = np.vstack(found) if found else np.zeros((0, 3))
    inverted = 1.0 - grey
    kept: list[tuple[float, float, float, float]] = []
    for u, v, r in candidates:
        flip = polarity == "light"
        u2, v2, r2, c = _refine(inverted if flip else grey, u, v, r)
        if polarity == "any" and c <= 0:
            flip = True
            u2, v2, r2, c = _refine(inverted, u, v, r)
        if c < min_contrast:
            continue
        u2, v2, r2 = _edge_circle(inverted if flip else grey, u2, v2, r2, c)
        if not r_min <= r2 <= r_max:
            continue
        # the same marker found at two levels: keep the first, which was found at the finer one
        if any(np.hypot(u2 - a, v2 - b) < 0.5 * min(r2, q) for a, b, q, _ in kept):
            continue
        kept.append((u2, v2, r2, -c if flip else c))
    arr = np.array(kept, dtype=np.float64).reshape(-1, 4)
    arr = arr[np.lexsort((arr[:, 0], arr[:, 1]))]
    return Circles(arr[:, :2], arr[:, 2], arr[:, 3])
