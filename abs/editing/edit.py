"""One edit, end to end: :func:`edit` (the Python API behind ``abs edit``).

The baseline is Khan et al. (2006), "Image-Based Material Editing" (docs/editing.md): from one
linear HDR photograph and the object's mask it estimates depth from luminance, normals, the
background behind the object and an environment map, then applies the target material's
transform and composites the object back.

Methods are looked up by name in :data:`METHODS` (:func:`register_method`): this module registers
``baseline``; :mod:`abs.resynthesis` (analysis by synthesis, a higher layer: it needs the renderer
and the fitter) registers ``synthesis`` when it is imported (``abs.edit`` and ``abs edit`` do).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from abs.colour.srgb import luminance
from abs.editing.brdf_replace import DEFAULT_SAMPLES, shade_with_brdf
from abs.editing.checks import check_mask, check_photograph, check_photograph_file
from abs.editing.depth import depth_from_luminance
from abs.editing.environment import environment_from_photograph
from abs.editing.gloss import DIFFUSE_BETA, GLOSS_ALPHA, GLOSSIER_BETA, remap_gloss
from abs.editing.gradients import forward_differences, normals_from_gradients, reshape_gradients
from abs.editing.highlights import highlight_layer, highlight_mask, highlight_threshold
from abs.editing.holes import fill_background
from abs.editing.spec import MaterialSpec, parse_material
from abs.editing.texture import retexture
from abs.editing.transparency import (DARK_EXPONENT, FROSTED_BLUR, TRANSLUCENT_BLUR, blur, darken,
                                      see_through, transfer_colour)
from abs.editing.warp import default_strength, warp_coordinates
from abs.errors import InputError

__all__ = ["METHODS", "EditSettings", "EditResult", "edit", "register_method", "Estimates",
           "estimate"]

METHODS: dict[str, Callable] = {}
"""Edit methods by name: ``function(rgb, mask, spec, settings, estimates, texture) -> EditResult``
(``rgb``, ``mask`` checked; ``estimates`` the baseline's :class:`Estimates`)."""

KNOWN_ELSEWHERE = {"synthesis": "abs.resynthesis"}
"""Methods registered by a module above this layer: named in the error when not imported."""


def register_method(name: str, function: Callable) -> Callable:
    """Make ``function`` the edit method ``name`` (see :data:`METHODS`); returns it."""
    METHODS[name] = function
    return function


@dataclass(frozen=True)
class EditSettings:
    """The baseline's parameters (defaults: the paper's values, or ours where it gives none).

    Attributes
    ----------
    reshape_times : int
        Applications of the gradient-boosting spline (paper: 1 to 4).
    spatial_fraction : float
        Bilateral spatial sigma as a fraction of the image width (paper: 0.001 to 0.008).
    sigma_range : float
        Bilateral range sigma in sigmoid units (our choice).
    relief : float
        Depth range relative to a sphere of the object's area (our scaling).
    gloss_alpha, glossier_beta, diffuse_beta : float
        The remapping's parameters (paper: 0.05, 20, 0.05).
    samples : int
        Environment directions per pixel for a MERL BRDF (paper: about 400).
    seed : int
        Seed of those directions.
    environment_width : int
        Width of the lat-long environment map, pixels.
    strength : float or None
        Warp ``s`` in pixels; ``None``: a quarter of the object's equivalent radius.
    texture_blend : float
        ``f`` of the matting equation (our default 0.1).
    dark_exponent : float
        ``a`` of dark glass (paper: 1.2 to 1.4).
    highlight_bins : int or None
        Bins of the luminance histogram for the highlight threshold (``None``: ``sqrt(pixels)``).
    highlight_threshold : float or None
        A luminance threshold to use instead of the histogram's (same unit as the photograph).
        The paper's rule marks the upper flank of a broad body-colour distribution as highlight
        (under environment light, half of a plastic sphere: benchmarks/material_edit.py).
    merl_dir : str or None
        Folder of real MERL ``.binary`` files; ``None``: the shared neural fits.
    synthesis : object or None
        The ``synthesis`` method's settings (:class:`abs.resynthesis.SynthesisSettings`);
        ``None``: its defaults. The baseline ignores it.
    """

    reshape_times: int = 1
    spatial_fraction: float = 0.008
    sigma_range: float = 0.1
    relief: float = 1.0
    gloss_alpha: float = GLOSS_ALPHA
    glossier_beta: float = GLOSSIER_BETA
    diffuse_beta: float = DIFFUSE_BETA
    samples: int = DEFAULT_SAMPLES
    seed: int = 0
    environment_width: int = 256
    strength: float | None = None
    texture_blend: float = 0.1
    dark_exponent: float = DARK_EXPONENT
    highlight_bins: int | None = None
    highlight_threshold: float | None = None
    merl_dir: str | None = None
    synthesis: object | None = None


@dataclass(frozen=True)
class Estimates:
    """What the baseline reads from the photograph, the starting point of every method (linear,
    docs/conventions.md frames).

    Attributes
    ----------
    depth : np.ndarray
        ``(height, width)`` depth towards the viewer, pixels.
    normals : np.ndarray
        ``(height, width, 3)`` unit normals, camera frame (x right, y down, z forward).
    background : np.ndarray
        ``(height, width, 3)`` the photograph with the object's hole filled.
    environment : np.ndarray
        ``(W/2, W, 3)`` lat-long map in abs's convention (camera along world +z).
    highlight_threshold : float
        Luminance above which object pixels are highlights.
    highlights : np.ndarray
        ``(height, width)`` bool, the highlight pixels.
    gradients : tuple of np.ndarray
        The reshaped depth gradients ``(g_x, g_y)``.
    strength : float
        The warp ``s``, pixels.
    """

    depth: np.ndarray
    normals: np.ndarray
    background: np.ndarray
    environment: np.ndarray
    highlight_threshold: float
    highlights: np.ndarray
    gradients: tuple[np.ndarray, np.ndarray]
    strength: float


@dataclass
class EditResult:
    """An edit and the estimates it was made from.

    ``depth``, ``normals``, ``background``, ``environment``, ``highlight_threshold`` and
    ``highlights`` are those of :attr:`estimates` (:class:`Estimates`); a method that fits the
    light hands back its fitted map as ``environment``.

    Attributes
    ----------
    image : np.ndarray
        ``(height, width, 3)`` the edited photograph, linear.
    material : MaterialSpec
        The target.
    mask : np.ndarray
        ``(height, width)`` bool, the object.
    estimates : Estimates
        What the edit was made from.
    settings : EditSettings
        The parameters used.
    method : str
        The method that made it.
    trust : dict or None
        Analysis by synthesis: the fit of the current material (residual RMSE against the
        photograph's noise, fitted parameters; :mod:`abs.resynthesis`). ``None`` for the
        baseline, which has no measure of its own error.
    """

    image: np.ndarray
    material: MaterialSpec
    mask: np.ndarray
    estimates: Estimates
    settings: EditSettings = field(default_factory=EditSettings)
    method: str = "baseline"
    trust: dict | None = None

    def __getattr__(self, name: str):
        # The estimates' fields read as the result's own (result.depth, result.environment, ...).
        if name in Estimates.__dataclass_fields__:
            return getattr(self.estimates, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


def _read_photo(photo) -> tuple[np.ndarray, Path | None]:
    if isinstance(photo, (str, Path)):
        from abs.io.images import read_image

        path = Path(photo)
        check_photograph_file(path)  # before decoding: a PNG decodes fine but is LDR
        return read_image(path), path
    return np.asarray(photo), None


def _read_mask(mask, shape) -> tuple[np.ndarray, Path | None]:
    if isinstance(mask, (str, Path)):
        from abs.io.images import read_image

        path = Path(mask)
        # Any channel nonzero marks the object; read as linear values (0 stays 0).
        return read_image(path).max(axis=-1), path
    return np.asarray(mask), None


def _texture(spec: MaterialSpec, texture: np.ndarray | None) -> np.ndarray:
    if texture is not None:
        return np.asarray(texture, np.float32)
    from abs.io.images import read_image

    return read_image(Path(spec.argument))


def edit(photo, mask, to: str | MaterialSpec = "glossier", method: str = "baseline", *,
         settings: EditSettings | None = None, texture: np.ndarray | None = None) -> EditResult:
    """Give the object in an HDR photograph a new material.

    Parameters
    ----------
    photo : np.ndarray or str or Path
        ``(height, width, 3)`` linear HDR RGB, or an ``.exr``/``.hdr`` file.
    mask : np.ndarray or str or Path
        ``(height, width)`` object mask (nonzero, or above half its maximum, is the object) or an
        image file of one; it must not touch the image border.
    to : str or MaterialSpec
        Target material (:mod:`abs.editing.spec`: ``glossier``, ``diffuse``, ``glass:clear``,
        ``glass:frosted``, ``glass:tinted``, ``glass:dark``, ``translucent``, ``merl:NAME``,
        ``texture:FILE``).
    method : str
        A name in :data:`METHODS`: ``"baseline"`` (Khan et al. 2006) or, once
        :mod:`abs.resynthesis` is imported, ``"synthesis"`` (analysis by synthesis).
    settings : EditSettings, optional
        Parameters; the defaults otherwise.
    texture : np.ndarray, optional
        With ``texture:...``: the texture as an array instead of reading the file.

    Returns
    -------
    EditResult

    Raises
    ------
    InputError
        For an LDR photograph, a mask that does not fit or touches the border or is empty, an
        unknown material or method.
    """
    settings = settings or EditSettings()
    spec = to if isinstance(to, MaterialSpec) else parse_material(to)
    if method not in METHODS:
        hint = (f"; {method!r} is registered by {KNOWN_ELSEWHERE[method]}: import it, or call "
                f"abs.edit" if method in KNOWN_ELSEWHERE else "")
        known = sorted(set(METHODS) | set(KNOWN_ELSEWHERE))
        raise InputError(None, "method", f"unknown method {method!r}; expected one of "
                                         f"{', '.join(known)}{hint}")
    rgb, photo_path = _read_photo(photo)
    rgb = check_photograph(rgb, photo_path)
    raw_mask, mask_path = _read_mask(mask, rgb.shape)
    m = check_mask(raw_mask, rgb.shape, mask_path)
    result = METHODS[method](rgb, m, spec, settings, estimate(rgb, m, settings), texture)
    result.method = method
    return result


def estimate(rgb: np.ndarray, m: np.ndarray, settings: EditSettings) -> Estimates:
    """The baseline's estimates from a checked photograph and mask (docs/editing.md, steps 2-6)."""
    lum = luminance(rgb)
    depth = depth_from_luminance(rgb, m, spatial_fraction=settings.spatial_fraction,
                                 sigma_range=settings.sigma_range, relief=settings.relief)
    gx, gy = reshape_gradients(*forward_differences(depth, m), times=settings.reshape_times)
    normals = normals_from_gradients(gx, gy)
    background = fill_background(rgb, m)
    environment = environment_from_photograph(background, settings.environment_width)
    threshold = (highlight_threshold(lum, m, settings.highlight_bins)
                 if settings.highlight_threshold is None else float(settings.highlight_threshold))
    strength = default_strength(m) if settings.strength is None else settings.strength
    return Estimates(depth, normals, background, environment, threshold,
                     highlight_mask(lum, m, threshold), (gx, gy), strength)


def _baseline(rgb: np.ndarray, m: np.ndarray, spec: MaterialSpec, settings: EditSettings,
              est: Estimates, texture: np.ndarray | None) -> EditResult:
    """Khan et al. (2006): the target material's image-space transform (docs/editing.md)."""
    background, environment, normals = est.background, est.environment, est.normals
    threshold, strength = est.highlight_threshold, est.strength
    gx, gy = est.gradients
    if spec.kind in ("glossier", "diffuse"):
        beta = settings.glossier_beta if spec.kind == "glossier" else settings.diffuse_beta
        image = remap_gloss(rgb, m, threshold, settings.gloss_alpha, beta)
    elif spec.kind == "merl":
        from abs.brdf.measured import measured_material_names, measured_table

        names = measured_material_names(settings.merl_dir)
        if spec.argument not in names:
            raise InputError(settings.merl_dir, "to", f"unknown MERL material {spec.argument!r}; "
                                                      f"known: {', '.join(names)}")
        shaded = shade_with_brdf(normals, m, environment, measured_table(spec.argument,
                                                                         settings.merl_dir),
                                 settings.samples, settings.seed)
        image = np.where(m[..., None], shaded, rgb)
    elif spec.kind == "texture":
        tx, ty = warp_coordinates(gx, gy, strength)
        image = retexture(rgb, m, _texture(spec, texture), tx, ty, threshold,
                          settings.texture_blend)
    else:  # glass, translucent
        tx, ty = warp_coordinates(gx, gy, strength)
        seen = see_through(background, tx, ty)
        variant = spec.argument if spec.kind == "glass" else "translucent"
        if variant == "frosted":
            seen = blur(seen, m, FROSTED_BLUR)
        elif variant == "translucent":
            seen = blur(seen, m, TRANSLUCENT_BLUR)
        elif variant == "tinted":
            source = (rgb - highlight_layer(rgb, m, threshold))[m]
            seen[m] = transfer_colour(seen[m], source)
        elif variant == "dark":
            seen = darken(seen, m, settings.dark_exponent)
        image = np.where(m[..., None], seen + highlight_layer(rgb, m, threshold), rgb)

    return EditResult(np.asarray(image, np.float32), spec, m, est, settings)


register_method("baseline", _baseline)
