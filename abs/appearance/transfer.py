"""Transfer: make an image from renderer A look as renderer B would render it.

Per object (material id) and θ bin, after the paper (issue 29): remove A's filter and apply B's.
With ``x`` a pixel of an object of class c in bin b, channel k, ``E`` the object's mean
(its energy) in the image and ``x̄ = x / E``:

- the bin's normalised mean moves by ``λ_A − λ_B`` (B's profile over θ instead of A's),
- its spread about that mean is scaled so its variance changes by ``ψ_B − ψ_A``,
- the object's energy is multiplied by ``ρ``, the mean of ``α_B / α_A`` over the object's bins
  weighted by the light in each bin of the image.

A pure per-channel gain ``g`` (a white balance, an exposure) gives ``α_B = g α_A`` and unchanged
λ, ψ, so the transfer is exactly ``x -> g x``.

The spread step is off by default (``spread=False``): at the sample counts abs characterises
with, ψ is mostly Monte-Carlo noise and fireflies, and ψ_B − ψ_A then adds noise rather than
look (benchmarks/appearance_transfer.py measures both).

Per-channel statistics cannot express a filter that mixes channels (a camera's colour matrix):
the gain of a channel then depends on the surface's colour, and a class characterised on a red
and a blue sample mis-predicts a green one. ``colour_matrix="global"`` first maps A's colours
through one 3x3 matrix fitted by weighted least squares on every class's per-scene θ-profile
means (the same design rendered by both renderers), and ``"class"`` through one matrix per class;
the θ transfer then corrects what remains. Both need the two files to share a design.

How the mean shift meets the pixels (``shift``, a registry, :data:`SHIFTS`): the paper states
λ as a shift of the bin's normalised *mean*. ``"ratio"`` (the default) scales every pixel of the
bin by ``(μ + λ_A − λ_B) / μ``; ``"additive"`` adds ``λ_A − λ_B`` to every pixel. Both move the
bin mean by the same amount. They differ within a bin whose pixels spread widely (a metal
reflecting bright sky and dark walls, a highlight): the additive shift moves a dark pixel as far
as a bright one and can push it below zero (the benchmark counted 21 such pixels for the Mitsuba
target and 108 for the camera with the additive form), while the ratio keeps every pixel's
contrast to its bin mean, is exact for any filter that multiplies by a function of θ, and never
makes a pixel negative. Measured on the benchmark it lowers the per-pixel ΔE00 on every target,
identity included.

The sensor step (``sensor``, :mod:`abs.appearance.sensor`) goes first, before everything: a
filter of the pixel's radiance and image position (vignetting, a colour matrix, a per-channel
response), fitted on the two characterisations' block means of the same design images. It acts
on the whole image (background too: a camera sees everything through its lens and sensor). The θ
statistics of A are then carried through it approximately (:func:`_through_sensor`), so the θ
transfer corrects only what the sensor step leaves; ``theta=False`` skips the θ transfer (the
sensor step alone, for a target that is a camera on A's renderings).

The normal step (``normals``, :mod:`abs.appearance.normals`) goes last: per class, θ bin and
azimuth φ of the normal, how B shares a bin's light out over φ compared with A (sharper or
blurrier reflections of the environment), for the classes where that predicts across halves of
the design. It holds only under the characterisation's own lighting, and is off by default.

Pixels with id 0 (background, silhouettes) are otherwise left as they are; bins that either
characterisation has no pixels in keep their normalised values.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from abs.appearance.geometry import Geometry
from abs.appearance.normals import apply_normal_gains, normal_gains
from abs.appearance.sensor import Sensor, fit_sensor
from abs.appearance.statistics import Characterisation, bin_moments, object_bins
from abs.errors import InputError

__all__ = ["COLOUR_MATRICES", "SHIFTS", "transfer", "colour_matrices", "check_compatible",
           "sensor_step", "normal_step"]

_MAX_SPREAD_SCALE = 4.0  # a bin whose spread would grow more than this is noise, not a filter
COLOUR_MATRICES = ("none", "class", "global")
"""The colour-matrix steps :func:`transfer` knows (see the module docstring)."""


def _shift_additive(xb, mu, shift, scale):
    """λ added to every pixel of the bin (the paper's mean shift, pixel by pixel)."""
    return mu + shift + (xb - mu) * scale


def _shift_ratio(xb, mu, shift, scale):
    """Every pixel of the bin scaled so the bin mean moves by λ (never below zero)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.where(mu > 1e-12, np.maximum(mu + shift, 0.0) / mu, 1.0)
    return (mu + (xb - mu) * scale) * factor


SHIFTS: dict[str, Callable] = {"ratio": _shift_ratio, "additive": _shift_additive}
"""How λ moves a bin's pixels (see the module docstring): ``f(x̄, μ, λ_A − λ_B, spread scale)``."""


def check_compatible(source: Characterisation, target: Characterisation, need_design: bool) -> None:
    """Refuse two characterisations a transfer cannot combine."""
    if not np.allclose(source.theta_edges, target.theta_edges):
        raise InputError(None, "theta_edges", "the two characterisations use different θ bins")
    if need_design and source.design != target.design:
        raise InputError(None, "design", f"the colour matrix needs both characterisations on one "
                                         f"design ({source.design} vs {target.design})")


def colour_matrices(source: Characterisation, target: Characterisation,
                    pooled: bool = False) -> dict[str, np.ndarray]:
    """Per class, the 3x3 matrix M minimising Σ w |M a − y|² over scenes and θ bins.

    ``a`` is A's mean colour of a class in a θ bin of a characterisation scene, ``y`` B's mean
    colour there, ``w = n / |y|²`` (relative errors, so dark bins count as much as bright ones).
    ``pooled``: one matrix fitted on every class's bins at once (a camera's colour matrix is one
    for all materials, and many colours condition it better). Fewer than 6 bins: the identity.
    """
    check_compatible(source, target, need_design=True)
    rows = {}
    for cls in source.classes:
        ca, cb = source.class_index(cls), target.class_index(cls)
        if cb is None:
            continue
        a, y = source.profiles[:, ca], target.profiles[:, cb]
        n = np.minimum(source.profile_counts[:, ca], target.profile_counts[:, cb])
        ok = (n > 0) & np.isfinite(a).all(-1) & np.isfinite(y).all(-1)
        rows[cls] = (a[ok], y[ok], n[ok])
    if pooled:
        a, y, n = (np.concatenate([r[i] for r in rows.values()]) for i in range(3))
        m = _fit(a, y, n)
        return {cls: m for cls in rows}
    return {cls: _fit(*r) for cls, r in rows.items()}


def _fit(a: np.ndarray, y: np.ndarray, n: np.ndarray) -> np.ndarray:
    if len(n) < 6:
        return np.eye(3)
    w = np.sqrt(n / np.maximum(np.sum(y ** 2, axis=-1), 1e-12))[:, None]
    return np.linalg.lstsq(a * w, y * w, rcond=None)[0].T


def _through_matrices(source: Characterisation, matrices: dict[str, np.ndarray]) -> Characterisation:
    """``source`` as if its images had been multiplied by each class's matrix.

    α follows exactly from the per-scene profiles (the sums of I are linear in I); λ and ψ are
    kept, which is exact for a diagonal matrix and close for one that mixes channels a little.
    """
    alpha, profiles = source.alpha.copy(), source.profiles.copy()
    for cls, m in matrices.items():
        c = source.class_index(cls)
        sums = np.nansum(source.profile_counts[:, c, :, None] * source.profiles[:, c], axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            light = sums / source.alpha[c]
            alpha[c] = np.where(source.counts[c][:, None] > 0, (sums @ m.T) / light, np.nan)
        profiles[:, c] = source.profiles[:, c] @ m.T
    return replace(source, alpha=alpha, profiles=profiles)


def sensor_step(source: Characterisation, target: Characterisation) -> Sensor:
    """The sensor step from ``source``'s renderer to ``target``'s, fitted on their block means.

    Both must be characterised on one design (their design digests equal) by a version of abs
    that stores block means; the fit takes seconds to a minute, so fit once and pass the result
    to :func:`transfer` for many images.
    """
    check_compatible(source, target, need_design=True)
    for c, role in ((source, "--from"), (target, "--to")):
        if c.blocks is None:
            raise InputError(None, "blocks", f"the {role} characterisation ({c.renderer}) has no block "
                                             f"means: characterise it again with this version of abs")
    return fit_sensor(source.blocks, target.blocks)


def normal_step(source: Characterisation, target: Characterisation, sensor: Sensor | None = None):
    """The normal step's gains per class and its split test per class
    (:func:`abs.appearance.normals.normal_gains`); both files on one design, with φ sums.
    ``sensor``: the sensor step that goes before it, if any (A's sums are carried through it)."""
    check_compatible(source, target, need_design=True)
    for c, role in ((source, "--from"), (target, "--to")):
        if c.phi_sums is None:
            raise InputError(None, "phi_sums", f"the {role} characterisation ({c.renderer}) has no "
                                               f"φ sums: characterise it again with this version of abs")
    if source.phi_sums.shape[3] != target.phi_sums.shape[3]:
        raise InputError(None, "phi_sums", "the two characterisations use different φ bins")
    if sensor is not None:
        source = _through_sensor(source, sensor)
    return normal_gains(source, target)


def _through_sensor(source: Characterisation, sensor: Sensor) -> Characterisation:
    """``source`` as if its images had been passed through ``sensor`` (approximately).

    From the per-scene profiles: α as for :func:`_through_matrices`, with the sensor applied to
    each bin's mean colour; λ moved by the change of each bin's normalised mean (per scene, count
    weighted, as λ itself is pooled). Approximate twice over: the response of a bin's mean is not
    the mean response of its pixels where the pixels spread, and the profiles carry no image
    position, so vignetting is taken at the image centre, where the design's sphere sits
    (v = 1). ψ is kept.
    """
    alpha, lam, profiles = source.alpha.copy(), source.lam.copy(), source.profiles.copy()
    for c in range(len(source.classes)):
        n = source.profile_counts[:, c].astype(float)
        prof = source.profiles[:, c]
        has = (n > 0) & np.isfinite(prof).all(-1)
        out = np.where(has[..., None], sensor.curve(np.nan_to_num(prof) @ sensor.matrix.T), np.nan)
        w = np.where(has, n, 0.0)[..., None]
        with np.errstate(invalid="ignore", divide="ignore"):
            e_in = np.nansum(w * prof, axis=1) / w.sum(1)          # per scene: object energy
            e_out = np.nansum(w * out, axis=1) / w.sum(1)
            moved = np.nansum(w * (prof / e_in[:, None] - out / e_out[:, None]), axis=0) / w.sum(0)
            sums = np.nansum(w * prof, axis=0)
            light = sums / source.alpha[c]
            alpha[c] = np.where(source.counts[c][:, None] > 0, np.nansum(w * out, axis=0) / light, np.nan)
        lam[c] = np.where(source.counts[c][:, None] > 0, source.lam[c] + np.nan_to_num(moved), np.nan)
        profiles[:, c] = out
    phi_sums = source.phi_sums
    if phi_sums is not None:  # each cell's mean colour through the sensor, as for the profiles
        n = source.phi_counts[..., None].astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(n > 0, phi_sums / np.where(n > 0, n, 1.0), 0.0)
        phi_sums = np.where(n > 0, n * sensor.curve(means @ sensor.matrix.T), 0.0)
    return replace(source, alpha=alpha, lam=lam, profiles=profiles, phi_sums=phi_sums)


def transfer(image: np.ndarray, geometry: Geometry, source: Characterisation,
             target: Characterisation, colour_matrix: str = "none", spread: bool = False,
             shift: str = "ratio", sensor: Sensor | bool = False, theta: bool = True,
             normals: bool = False) -> np.ndarray:
    """``image`` (from ``source``'s renderer) as ``target``'s renderer would show it.

    Parameters
    ----------
    image : np.ndarray
        ``(height, width, 3)`` linear RGB.
    geometry : Geometry
        θ and material ids of its pixels (same height and width).
    source, target : Characterisation
        Renderer A's and renderer B's statistics.
    colour_matrix : {"none", "class", "global"}
        The colour-matrix step first (:func:`colour_matrices`; the module docstring).
    spread : bool
        Also apply the spread step (ψ).
    shift : {"ratio", "additive"}
        How λ moves the pixels of a bin (:data:`SHIFTS`; the module docstring).
    sensor : Sensor or bool
        The sensor step first (:mod:`abs.appearance.sensor`): a fitted :class:`Sensor`
        (:func:`sensor_step`), True to fit one here (slow: fit once for many images), or False.
    theta : bool
        Apply the per-class θ transfer (α, λ, ψ); False leaves only the steps before it.
    normals : bool
        Then the normal step (:func:`normal_step`): only for images lit as the design was.

    Returns
    -------
    np.ndarray
        float32, same shape.
    """
    if image.shape[:2] != geometry.ids.shape:
        raise InputError(None, "geometry", f"image is {image.shape[:2]}, geometry {geometry.ids.shape}")
    if colour_matrix not in COLOUR_MATRICES:
        raise InputError(None, "colour_matrix", f"expected one of {COLOUR_MATRICES}, got {colour_matrix!r}")
    if shift not in SHIFTS:
        raise InputError(None, "shift", f"expected one of {tuple(SHIFTS)}, got {shift!r}")
    check_compatible(source, target,
                     need_design=colour_matrix != "none" or sensor is not False or normals)
    if normals and not theta:
        raise InputError(None, "normals", "the normal step refines the θ transfer: it needs theta=True")
    out = np.array(image, np.float64)
    if sensor is True:
        sensor = sensor_step(source, target)
    if isinstance(sensor, Sensor):
        # The sensor acts on radiance and position, before the material-wise steps.
        out = sensor.apply(out)
        source = _through_sensor(source, sensor)
    if not theta and colour_matrix == "none":
        return out.astype(np.float32)
    matrices = {}
    if colour_matrix != "none":
        # The matrix acts first, on the raw colours, as a camera's does before its response.
        matrices = colour_matrices(source, target, pooled=colour_matrix == "global")
        source = _through_matrices(source, matrices)
    n_bins = source.n_bins
    for obj, mask, bins in object_bins(geometry, source.theta_edges):
        cls = geometry.classes[obj - 1]
        ca, cb = source.class_index(cls), target.class_index(cls)
        if ca is None or cb is None:
            raise InputError(None, "classes", f"class {cls!r} is not characterised in both files")
        x = out[mask]
        if cls in matrices:
            x = x @ matrices[cls].T
        if not theta:
            out[mask] = x
            continue
        energy = x.mean(axis=0)
        energy = np.where(energy > 0, energy, 1.0)
        xb = x / energy
        n, mu, var = bin_moments(xb, bins, n_bins)
        _, light, _ = bin_moments(x, bins, n_bins)
        ok = (n > 0) & (source.counts[ca] > 0) & (target.counts[cb] > 0)
        gain = np.where(ok[:, None], target.alpha[cb] / np.where(ok[:, None], source.alpha[ca], 1.0), 1.0)
        weight = np.where(ok[:, None], n[:, None] * light, 0.0)
        rho = np.where(weight.sum(0) > 0, (weight * gain).sum(0) / np.maximum(weight.sum(0), 1e-300), 1.0)
        lam_shift = np.where(ok[:, None], source.lam[ca] - target.lam[cb], 0.0)
        var_t = np.maximum(var - np.where(ok[:, None], source.psi[ca] - target.psi[cb], 0.0), 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(var > 1e-12, np.sqrt(var_t / var), 1.0)
        scale = np.clip(np.where(ok[:, None] & spread, scale, 1.0), 0.0, _MAX_SPREAD_SCALE)
        moved = SHIFTS[shift](xb, mu[bins], lam_shift[bins], scale[bins])
        out[mask] = moved * energy * rho
    if normals:
        gains, _ = normal_step(source, target)  # source: through the sensor when there is one
        out = apply_normal_gains(out, geometry, gains, source.theta_edges)
    return out.astype(np.float32)
