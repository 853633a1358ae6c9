"""The background behind the object: fill its hole with mirrored copies (Khan et al. 2006).

Per image row, each run of object pixels ``x_min < x < x_max`` (``x_min`` and ``x_max`` the
background pixels just left and right of the run) is filled with the mirror images of the
background about both ends, blended linearly across the run:

    L'(x, y) = w1 L(2 x_min - x, y) + w2 L(2 x_max - x, y),
    w1 = (x_max - x) / (x_max - x_min),    w2 = (x - x_min) / (x_max - x_min),

so the fill meets the background continuously on both sides. Column indices that leave the
image wrap around (the paper's rule): ``2 x_min - x < 0`` reads column ``W + 2 x_min - x``.

Our addition, for holes wider than the background beside them: a mirrored index that lands on an
object pixel (of any run) would copy the object into its own background; that copy's weight is
dropped and the other copy's weight raised to 1. Where both land on the object the nearest
background pixel of the row is used.
"""

from __future__ import annotations

import numpy as np

from abs.errors import InputError

__all__ = ["fill_background", "row_runs"]


def row_runs(row: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` column of each run of True values in a boolean row, inclusive."""
    row = np.asarray(row, bool)
    padded = np.concatenate([[False], row, [False]])
    edges = np.flatnonzero(padded[1:] != padded[:-1])
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


def fill_background(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The photograph with the object's pixels replaced by the mirrored background.

    Parameters
    ----------
    image : np.ndarray
        ``(height, width)`` or ``(height, width, channels)`` image (any unit).
    mask : np.ndarray of bool
        ``(height, width)`` object pixels. A row whose object touches the left or right image
        border has no background on that side; :func:`abs.editing.checks.check_mask` refuses such
        masks before this is called.

    Returns
    -------
    np.ndarray
        Same shape and dtype as ``image``, object pixels filled, others unchanged.

    Raises
    ------
    InputError
        If a row's object touches the left or right border, or a row is all object.
    """
    img = np.asarray(image)
    m = np.asarray(mask, bool)
    out = img.copy()
    width = m.shape[1]
    for y in np.flatnonzero(m.any(axis=1)):
        background = np.flatnonzero(~m[y])
        if background.size == 0:
            raise InputError(None, "mask", f"row {y} is all object: no background to fill from")
        for first, last in row_runs(m[y]):
            if first == 0 or last == width - 1:
                raise InputError(None, "mask", f"row {y}: the object touches the "
                                               f"{'left' if first == 0 else 'right'} border")
            x_min, x_max = first - 1, last + 1
            xs = np.arange(first, last + 1)
            w1 = (x_max - xs) / (x_max - x_min)
            w2 = (xs - x_min) / (x_max - x_min)
            left = (2 * x_min - xs) % width
            right = (2 * x_max - xs) % width
            ok1, ok2 = ~m[y, left], ~m[y, right]
            w1 = np.where(ok1, w1, 0.0)
            w2 = np.where(ok2, w2, 0.0)
            total = w1 + w2
            # One copy on the object: the other gets all the weight.
            w1 = np.divide(w1, total, out=np.zeros_like(w1), where=total > 0)
            w2 = np.divide(w2, total, out=np.zeros_like(w2), where=total > 0)
            values = (w1.reshape((-1,) + (1,) * (img.ndim - 2)) * img[y, left].astype(np.float64)
                      + w2.reshape((-1,) + (1,) * (img.ndim - 2)) * img[y, right].astype(np.float64))
            none = total <= 0
            if none.any():
                nearest = background[np.abs(background[None, :] - xs[none, None]).argmin(axis=1)]
                values[none] = img[y, nearest]
            out[y, xs] = values.astype(img.dtype)
    return out
