"""Gradients of the depth map, their reshaping, and surface normals (Khan et al. 2006, sec. 3).

- Forward differences ``gx = d'(x+1, y) - d'(x, y)``, ``gy = d'(x, y+1) - d'(x, y)`` on the
  image grid (x right, y down), zero where the step leaves the object.
- The paper reshapes the gradient field with a spline that boosts small and large gradients and
  applies it 1 to 4 times, because a bas-relief-like depth from luminance is flatter than the
  object and human vision tolerates the exaggeration. **Not found:** the spline's control points
  (the paper's figure, not its text, gives the curve; the text we could search names only its
  purpose). **Our choice** (:data:`SPLINE_KNOTS`): a monotone cubic (PCHIP) through
  ``(0, 0), (0.1, 0.2), (0.5, 0.55), (1, 1.4)`` of the gradient magnitude divided by its maximum
  over the object; small gradients are doubled, mid-range ones kept (x1.1), the largest raised
  by 40 %. The direction of each gradient is kept; each application renormalises by the new
  maximum.
- Normals ``n = g_x x g_y`` with ``g_x = [1, 0, dx]``, ``g_y = [0, 1, dy]``, i.e.
  ``(-dx, -dy, 1)`` in a frame whose z points to the viewer. abs returns them in its camera frame
  (docs/conventions.md: x right, y down, z forward, away from the camera), where that outward
  normal is ``(-dx, -dy, -1) / norm``.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PchipInterpolator

__all__ = ["SPLINE_KNOTS", "forward_differences", "reshape_gradients", "normals_from_gradients"]

SPLINE_KNOTS = ((0.0, 0.0), (0.1, 0.2), (0.5, 0.55), (1.0, 1.4))
"""Knots (normalised magnitude in, out) of the gradient-reshaping spline (our choice, above)."""


def forward_differences(depth: np.ndarray, mask: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Forward-difference gradients of a depth map, per pixel.

    Parameters
    ----------
    depth : np.ndarray
        ``(height, width)`` depth (pixels, or any unit: gradients have that unit per pixel).
    mask : np.ndarray of bool, optional
        The object's pixels; a difference is zero unless both its pixels are in the object.

    Returns
    -------
    gx, gy : np.ndarray
        ``(height, width)`` float64: ``d(x+1, y) - d(x, y)`` and ``d(x, y+1) - d(x, y)`` (image y
        down); 0 in the last column (gx) and last row (gy).
    """
    d = np.asarray(depth, np.float64)
    gx = np.zeros_like(d)
    gy = np.zeros_like(d)
    gx[:, :-1] = d[:, 1:] - d[:, :-1]
    gy[:-1, :] = d[1:, :] - d[:-1, :]
    if mask is not None:
        m = np.asarray(mask, bool)
        inside_x = np.zeros_like(m)
        inside_x[:, :-1] = m[:, 1:] & m[:, :-1]
        inside_y = np.zeros_like(m)
        inside_y[:-1, :] = m[1:, :] & m[:-1, :]
        gx[~inside_x] = 0.0
        gy[~inside_y] = 0.0
    return gx, gy


def reshape_gradients(gx: np.ndarray, gy: np.ndarray, times: int = 1,
                      knots=SPLINE_KNOTS) -> tuple[np.ndarray, np.ndarray]:
    """Apply the boosting spline to the gradient magnitudes ``times`` times (1 to 4 in the paper).

    Parameters
    ----------
    gx, gy : np.ndarray
        Gradients (unit per pixel).
    times : int
        Number of applications, >= 0 (0 returns copies).
    knots : sequence of (float, float)
        Spline knots on the magnitude normalised by its maximum (see the module docstring).

    Returns
    -------
    gx, gy : np.ndarray
        Reshaped gradients, same directions, same unit.
    """
    if times < 0:
        raise ValueError(f"times must be >= 0, got {times}")
    xs, ys = (np.array(v, np.float64) for v in zip(*knots))
    spline = PchipInterpolator(xs, ys)
    gx, gy = np.array(gx, np.float64), np.array(gy, np.float64)
    for _ in range(times):
        magnitude = np.hypot(gx, gy)
        peak = float(magnitude.max())
        if peak <= 0.0:
            break
        scaled = spline(np.clip(magnitude / peak, 0.0, 1.0)) * peak
        ratio = np.divide(scaled, magnitude, out=np.zeros_like(magnitude), where=magnitude > 0)
        gx, gy = gx * ratio, gy * ratio
    return gx, gy


def normals_from_gradients(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Unit normals ``g_x x g_y`` of a depth map's gradients, in abs's camera frame.

    Parameters
    ----------
    gx, gy : np.ndarray
        ``(height, width)`` slopes of the depth towards the viewer along image x (right) and
        image y (down), pixels per pixel.

    Returns
    -------
    np.ndarray
        ``(height, width, 3)`` unit normals (x right, y down, z away from the camera); a flat
        patch gives ``(0, 0, -1)``, facing the camera.
    """
    n = np.stack([-np.asarray(gx, np.float64), -np.asarray(gy, np.float64),
                  -np.ones(np.shape(gx))], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
