"""Path-length recordings: one render that gives the image at every absorption and light scale.

Beer-Lambert absorption only reweights light paths. A path that travels a total length ``L``
inside a glass of absorption ``sigma_c`` (1/m, colour channel ``c``) carries ``exp(-sigma_c L)``,
and nothing else in how it was sampled depends on ``sigma``: next-event estimation and MIS use
pdfs without it, and Russian roulette's survival probability follows the throughput without the
glass's vertices (:mod:`abs.render.integrator`), so its decisions are the same at any ``sigma``. With the same random numbers a
pixel's estimate is therefore exactly

    I_c(sigma) = sum_paths f_c exp(-(sigma_c - sigma_rec,c) L),

``f_c`` what the path brought at the recording absorption ``sigma_rec``. The environment's
scale multiplies all of it (the environment is the scenes' only light), and the sensor
(:mod:`abs.render.sensor`) acts after the path tracer. So one render that records, per pixel and
channel, how its light is distributed over in-glass length gives the image at every absorption,
scale and sensor setting, with derivatives in closed form (``-sum f L exp(-dsigma L)``).

Binning. Lengths are recorded on ``n_nodes`` equally spaced nodes ``L_k = k * spacing`` by linear
(tent) interpolation: light at length ``L`` between nodes ``k`` and ``k + 1`` is split between
them in proportion to its distance from each. Reweighting then evaluates ``exp(-dsigma L)`` at the
nodes, which is linear interpolation of the exponential: its relative error is at most
``(dsigma * spacing)^2 / 8`` (0.4 % for ``dsigma = 10 /m`` at 18 mm spacing) and always of one
sign (the exponential is convex), ``(dsigma * spacing)^2 / 12`` on average over light spread
evenly between nodes, which the nodes' weights divide out (all but node 0's). Paths never in glass
sit exactly on node 0. Light beyond the last node (long internal bounces, rare and faint) goes to
an overflow pair per pixel and channel, its sum and its length-weighted sum, and is reweighted at
its mean length. Memory: ``(n_nodes + 2)`` floats per pixel and channel.

The recording absorption. Reweighting to ``sigma >= sigma_rec`` multiplies every path by at most
1, so the variance of the reweighted image is at most the recording's; reweighting below it
boosts long paths by ``exp(+dsigma L)``. Recordings are therefore made at the lowest absorption a
fit may visit, 0 by default (:meth:`abs.render.CompiledScene.record`).

Several glasses. A path through two glass materials carries ``exp(-sigma_1 L_1 - sigma_2 L_2)``,
which no pair of separate length histograms can give (the two lengths of one path are not
independent: a path through the wine in a glass also crosses the glass). So a recording of
several materials keeps one length per material and bins the light jointly, on the product of
their nodes (tent weights in every length, :data:`JOINT_NODES` nodes each: ``(n + 2)^k`` floats
per pixel and channel). Reweighting contracts the lengths one material at a time; the overflow of
one material's lengths is reweighted at its mean length among the light in each of the other
materials' nodes, and its derivative holds that mean fixed (exact for one material; for several,
the error is confined to the overflow's light). At most :data:`MAX_MATERIALS` materials are
recorded together; glass beyond them absorbs at its current value as in any render (its
absorption is then not reweightable). Parameters that move paths (IOR, roughness, pose) need new
renders.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render.jit import opaque

__all__ = ["PathLengthRecording", "LengthBins", "length_bins", "bin_light", "reweight",
           "MAX_MATERIALS", "JOINT_NODES"]

#: Nodes per pixel and channel by default: 18 mm apart for the default scene's 4 cm sphere
#: (relative error of the reweighting at most 0.07 % for a change of 4 per metre, 0.4 % for 10).
DEFAULT_NODES = 32

#: Nodes per material when several materials' lengths are recorded jointly: 26^2 = 676 floats per
#: pixel and channel for two (156 MB at 160x120), 30 mm apart for the default scene's sphere
#: (relative error at most 0.2 % for a change of 4 per metre, 1.1 % for 10).
JOINT_NODES = 24

#: Most glass materials whose lengths one recording keeps (memory grows as nodes^materials).
MAX_MATERIALS = 2

#: Recorded lengths reach this many times the glass's bounding-box diagonal before overflowing.
_DIAGONALS = 4.0


@dataclass(frozen=True)
class LengthBins:
    """Where path lengths are recorded: ``n_nodes`` nodes ``k * spacing`` (metres), ``k = 0 ..``."""

    n_nodes: int
    spacing: float

    @property
    def slots(self) -> int:
        """Floats per pixel and channel: the nodes, the overflow sum and its length moment."""
        return self.n_nodes + 2


def length_bins(diagonal_m: float, n_nodes: int = DEFAULT_NODES) -> LengthBins:
    """Nodes for glass whose bounding box has diagonal ``diagonal_m`` (m): up to 4 diagonals.

    A path through a glass object crosses it about once per entry; paths with several internal
    reflections or re-entries reach a few diagonals, each reflection costing a Fresnel factor of
    a few per cent, so light beyond 4 diagonals is rare enough for the overflow's mean-length
    approximation.
    """
    if not diagonal_m > 0 or n_nodes < 2:
        raise ValueError(f"need a positive glass size and at least 2 nodes, not {diagonal_m} m "
                         f"and {n_nodes}")
    return LengthBins(int(n_nodes), _DIAGONALS * float(diagonal_m) / (n_nodes - 1))


def _tent(length: mi.Float, bins: LengthBins):
    """Where the light at ``length`` goes among one material's slots: two ``(slot, factor)``
    pairs, the nodes around ``length`` with tent weights, or past the last node the overflow's sum
    (factor 1) and length moment (factor ``length``)."""
    x = length * opaque(mi.Float, 1.0 / bins.spacing)
    below = dr.floor(x)
    over = x >= float(bins.n_nodes - 1)
    k = mi.UInt32(dr.select(over, 0.0, below))
    t = x - below
    return ((dr.select(over, bins.n_nodes, k), dr.select(over, 1.0, 1.0 - t)),
            (dr.select(over, bins.n_nodes + 1, k + 1), dr.select(over, length, t)))


def bin_light(histogram: mi.Float, pixel: mi.UInt32, light: mi.Color3f, lengths, bins) -> None:
    """Add each lane's ``light`` (per channel) at its in-glass ``lengths`` to ``histogram``.

    ``lengths`` and ``bins`` give one length (``mi.Float``, m) and one :class:`LengthBins` per
    recorded material. ``histogram`` holds ``prod(b.slots)`` floats per (pixel, channel), in
    (pixel, channel) order, the first material's slot varying slowest; the tent weights split the
    light between the nodes around each length (``2^k`` slots per lane). Inside a symbolic loop
    this is a masked side effect of the active lanes.
    """
    strides, size = [], 1
    for b in reversed(bins):
        strides.insert(0, size)
        size *= b.slots
    tents = [_tent(length, b) for length, b in zip(lengths, bins)]
    corners = [(mi.UInt32(0), mi.Float(1.0))]
    for tent, stride in zip(tents, strides):
        corners = [(offset + slot * stride, factor * f) for offset, factor in corners
                   for slot, f in tent]
    for c in range(3):
        value = light[c]
        live = value != 0.0
        base = (pixel * 3 + c) * size
        for offset, factor in corners:
            dr.scatter_reduce(dr.ReduceOp.Add, histogram, value * factor, base + offset, live)


@dataclass
class PathLengthRecording:
    """One view's light by pixel, channel and in-glass path length (see the module docstring).

    Attributes
    ----------
    histogram : ndarray, shape (height, width, 3, prod(b.slots for b in bins)), float32
        Light per node (per material: its nodes, then the overflow's sum and length moment; the
        first material's slot varying slowest), radiance units, already divided by the samples
        per pixel.
    bins : tuple of LengthBins
        One per recorded material.
    materials : tuple of str
        The glass materials whose lengths were recorded (empty: no glass; all light at 0).
    absorption_per_m : ndarray, shape (len(materials), 3)
        Each recorded material's absorption during the recording (1/m).
    env_scale : float
        The environment's scale during the recording.
    spp, seed : int
        The render's samples per pixel and seed.
    """

    histogram: np.ndarray
    bins: tuple[LengthBins, ...]
    materials: tuple[str, ...]
    absorption_per_m: np.ndarray
    env_scale: float
    spp: int
    seed: int

    @property
    def height(self) -> int:
        return self.histogram.shape[0]

    @property
    def width(self) -> int:
        return self.histogram.shape[1]

    @property
    def nbytes(self) -> int:
        return self.histogram.nbytes


def _contract(a: np.ndarray, bins: LengthBins, change: np.ndarray, derivative: bool,
              mean: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Reweight the last axis of ``a`` (one material's slots; axis 2 is the colour channel) by
    ``exp(-change_c L)``, or by its derivative in ``change_c`` when ``derivative``; removes it.

    The overflow is reweighted at its mean length, ``mean`` when given (a derivative of another
    material's length, contracted before, holds the primal's mean), else its length moment over
    its sum. Returns the result and the mean used."""
    nodes = bins.n_nodes
    lengths = np.arange(nodes) * bins.spacing
    # Tent binning evaluates exp(-change L) by linear interpolation between nodes, which
    # overestimates the convex exponential: for light spread evenly between two nodes the
    # interpolated sum is (b/2) coth(b/2) = 1 + b^2/12 + ... times the exact one (b = change *
    # spacing). Weights c = tanh(b/2) / (b/2) on the nodes divide that out (measured on the glass
    # suite's sphere-1.62, recording against a render with the same samples: the glass's pixels
    # 0.007, 0.04 and 0.11 % too bright in R, G, B without it, 20x less with it). Node 0 keeps
    # weight 1: its light is mostly paths that never entered glass, at exactly L = 0.
    half = 0.5 * change * bins.spacing  # (3,)
    small = np.abs(half) < 1e-4
    safe = np.where(small, 1.0, half)
    correction = np.where(small, 1.0 - half ** 2 / 3.0, np.tanh(half) / safe)
    inside = np.arange(nodes)[None, :] > 0
    at_nodes = np.exp(-change[:, None] * lengths[None, :])  # (3, nodes)
    weights = at_nodes * np.where(inside, correction[:, None], 1.0)
    if derivative:
        d_correction = 0.5 * bins.spacing * np.where(
            small, -2.0 * half / 3.0, (half / np.cosh(half) ** 2 - np.tanh(half)) / safe ** 2)
        weights = -weights * lengths + at_nodes * np.where(inside, d_correction[:, None], 0.0)
    middle = "defgh"[:a.ndim - 4]  # the other materials' axes, still to be contracted
    node_light = np.einsum(f"yxc{middle}k,ck->yxc{middle}", a[..., :nodes],
                           weights.astype(a.dtype))
    total = a[..., nodes].astype(np.float64)
    if mean is None:
        moment = a[..., nodes + 1].astype(np.float64)
        mean = np.divide(moment, total, out=np.zeros_like(total), where=total > 0)
    channel = change.reshape((1, 1, 3) + (1,) * (a.ndim - 4))
    overflow = total * np.exp(-channel * mean)
    return node_light + (-mean * overflow if derivative else overflow), mean


def _rows(value, k: int) -> np.ndarray:
    """``value`` as ``k`` rows of 3: per material and channel (one number or one row: every
    material alike)."""
    value = np.asarray(value, np.float64)
    return np.broadcast_to(value if value.ndim == 2 else np.broadcast_to(value, 3), (k, 3))


def reweight(recording: PathLengthRecording, absorption_per_m, env_scale: float,
             d_absorption=None, d_scale: float = 0.0) -> tuple[np.ndarray, np.ndarray | None]:
    """The recorded view's radiance at other absorptions and another environment scale.

    Parameters
    ----------
    recording : PathLengthRecording
    absorption_per_m : array-like, shape (len(recording.materials), 3)
        Each recorded material's absorption (1/m); one row may be given as shape (3,).
    env_scale : float
        The environment's scale.
    d_absorption : array-like, shape like ``absorption_per_m``, optional
        A tangent of the absorptions (1/m): the directional derivative along it (and
        ``d_scale``) is returned as well, in closed form (``-sum f L exp(-d sigma L)`` per
        material and channel).
    d_scale : float
        The scale's tangent.

    Returns
    -------
    image : ndarray, shape (height, width, 3), float64
        Linear RGB radiance (before the sensor).
    derivative : ndarray or None
        The directional derivative (same shape), when ``d_absorption`` is given.
    """
    if recording.env_scale <= 0.0:
        raise ValueError("a recording made at environment scale 0 holds no light to rescale")
    k = len(recording.materials)
    change = _rows(absorption_per_m, k) - recording.absorption_per_m.reshape(k, 3)
    ratio = float(env_scale) / recording.env_scale
    h = recording.histogram
    grid = h.reshape(h.shape[:3] + tuple(b.slots for b in recording.bins))

    means = [None] * k

    def image(differentiated: int | None) -> np.ndarray:
        a = grid
        for m in reversed(range(k)):  # the last material's axis is the array's last
            # Below a differentiated material, the overflow keeps the primal's mean length.
            held = means[m] if differentiated is not None and m < differentiated else None
            a, mean = _contract(a, recording.bins[m], change[m], m == differentiated, held)
            if differentiated is None:
                means[m] = mean
        return a.astype(np.float64).reshape(h.shape[:3])

    radiance = image(None)
    if d_absorption is None:
        return ratio * radiance, None
    tangent = _rows(d_absorption, k)
    derivative = radiance * (float(d_scale) / recording.env_scale)
    for m in range(k):
        if np.any(tangent[m] != 0):
            derivative = derivative + image(m) * tangent[m] * ratio
    return ratio * radiance, derivative
