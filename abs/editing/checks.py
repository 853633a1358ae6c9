"""Input checks of an edit: the photograph must be HDR, the mask must fit it and leave a border.

Every failure is an :class:`abs.errors.InputError` naming the file (when there is one) and the
field, so the message alone says what to fix:

- an LDR photograph: a PNG or JPEG file (8- or 16-bit display-referred sRGB), or values that look
  clipped at 1.0. The method reads shape from luminance and lights the new material with the
  photograph's own radiance, so clipped highlights and a compressed tone curve break it: it needs
  a linear HDR photograph (OpenEXR or Radiance ``.hdr``, e.g. merged from an exposure bracket with
  ``abs capture``/``abs.acquisition.hdr``);
- a mask whose size differs from the photograph's;
- an empty mask;
- a mask touching the image border: the hole filling copies background from both sides of the
  object and the environment is read from around it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from abs.colour.srgb import as_rgb_image
from abs.errors import InputError

__all__ = ["LDR_EXTENSIONS", "check_photograph_file", "check_photograph", "check_mask",
           "looks_clipped"]

LDR_EXTENSIONS = (".png", ".jpg", ".jpeg")
"""Display-referred formats refused as photographs."""

_HDR_HINT = ("image-based material editing needs a linear HDR photograph (OpenEXR .exr or "
             "Radiance .hdr): it reads the shape from luminance and lights the new material with "
             "the photograph's own radiance, which clipping and display encoding destroy")


def looks_clipped(rgb: np.ndarray, level: float = 1.0, tolerance: float = 1.0 / 512,
                  min_fraction: float = 1e-3, min_pixels: int = 4) -> bool:
    """Whether an image's values stop at ``level`` as an LDR image's do.

    True when no value exceeds ``level`` (plus a rounding margin) and at least ``max(min_pixels,
    min_fraction * pixels)`` pixels have a channel within ``tolerance`` of it: a plateau at the top,
    where an HDR image has a tail.

    Parameters
    ----------
    rgb : np.ndarray
        ``(height, width, 3)`` linear RGB.
    level : float
        The clipping value (1.0 for display images).
    tolerance : float
        How close to ``level`` counts as at it (half an 8-bit step by default).
    min_fraction, min_pixels : float, int
        How many pixels at the level make a plateau.
    """
    peak = rgb.max(axis=-1)
    if float(peak.max()) > level + 1e-6:
        return False
    at_top = int(np.count_nonzero(peak >= level - tolerance))
    return at_top >= max(min_pixels, int(np.ceil(min_fraction * peak.size)))


def check_photograph_file(path: str | Path) -> None:
    """Refuse a photograph file in a display (LDR) format (PNG, JPEG) before decoding it.

    Raises
    ------
    InputError
        Field ``format``, saying that the method needs HDR.
    """
    suffix = Path(path).suffix.lower()
    if suffix in LDR_EXTENSIONS:
        raise InputError(path, "format", f"{suffix} is a display (LDR) format; {_HDR_HINT}")


def check_photograph(rgb: np.ndarray, source: str | Path | None = None) -> np.ndarray:
    """The photograph as float32 ``(height, width, 3)``, refused if it is LDR.

    Parameters
    ----------
    rgb : np.ndarray
        Linear RGB.
    source : str or Path, optional
        The file it came from (for the messages, and its extension is checked).

    Raises
    ------
    InputError
        If the file is a PNG/JPEG, the array is not an RGB image, it holds non-finite or
        negative-only values, or its values look clipped at 1.0.
    """
    if source is not None:
        check_photograph_file(source)
    arr = np.asarray(as_rgb_image(rgb), np.float32)
    if not np.all(np.isfinite(arr)):
        raise InputError(source, "pixels", "non-finite values (NaN or Inf)")
    if float(arr.max()) <= 0.0:
        raise InputError(source, "pixels", "the photograph is black")
    if looks_clipped(arr):
        raise InputError(source, "pixels", "values stop at 1.0 with a plateau of clipped pixels, "
                                           f"as in an LDR image; {_HDR_HINT}")
    return arr


def check_mask(mask: np.ndarray, shape: tuple[int, ...], source: str | Path | None = None) -> np.ndarray:
    """The object mask as bool ``(height, width)``, checked against its photograph.

    Parameters
    ----------
    mask : np.ndarray
        ``(height, width)`` (or with a channel axis: any nonzero channel) mask or alpha matte;
        values above 0.5 of its maximum are the object.
    shape : tuple of int
        The photograph's shape.
    source : str or Path, optional
        The mask's file, for the messages.

    Raises
    ------
    InputError
        Field ``size`` if it does not match the photograph, ``pixels`` if it is empty or touches
        the image border.
    """
    arr = np.asarray(mask)
    if arr.ndim == 3:
        arr = arr.max(axis=-1)
    if arr.ndim != 2:
        raise InputError(source, "size", f"expected a (height, width) mask, got shape {arr.shape}")
    height, width = int(shape[0]), int(shape[1])
    if arr.shape != (height, width):
        raise InputError(source, "size", f"mask is {arr.shape[1]}x{arr.shape[0]} pixels but the "
                                         f"photograph is {width}x{height}")
    values = arr.astype(np.float64)
    top = float(values.max()) if values.size else 0.0
    m = values > 0.5 * top if top > 0 else np.zeros(arr.shape, bool)
    if not m.any():
        raise InputError(source, "pixels", "the mask is empty: mark the object's pixels nonzero")
    sides = {"top": m[0].any(), "bottom": m[-1].any(), "left": m[:, 0].any(),
             "right": m[:, -1].any()}
    touching = [name for name, hit in sides.items() if hit]
    if touching:
        raise InputError(source, "pixels", f"the mask touches the image border ({', '.join(touching)}"
                                           "): the method fills the hole from the background on "
                                           "both sides of the object and reads the environment "
                                           "around it; leave at least one background pixel on "
                                           "every side")
    return m
