"""The seed papers' baseline: one-parameter RMSE scans, one colour channel at a time.

For each channel ``c`` of a parameter (or its only scalar), every other value stays at the
scene's, and channel ``c`` steps through a grid; each grid value is rendered at low resolution
on the training views and scored by the RMSE of colour channel ``c`` (the channel it changes). The
estimate is the minimum of a parabola through the best grid point and its two neighbours. All
grid points use the same render seeds, so the scan curve is smooth (common random numbers).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from abs.model import build_model, typical_step

__all__ = ["scan", "ScanResult", "default_grid", "channel_curves"]


@dataclass(frozen=True)
class ScanResult:
    """Per-channel scans of one parameter.

    Attributes
    ----------
    name, unit : str
    grids, rmse : list of ndarray
        Per channel: the scanned values and the RMSE (linear RGB; of the residuals as the
        problem weighs them, :attr:`abs.model.FitProblem.weights`) at each.
    minimum : ndarray
        Per channel: the estimated minimiser.
    renders, samples_rendered : int
    wall_s : float
    """

    name: str
    unit: str
    grids: list[np.ndarray]
    rmse: list[np.ndarray]
    minimum: np.ndarray
    renders: int
    samples_rendered: int
    wall_s: float

    def summary(self) -> dict:
        """``scan.json``."""
        return {"parameter": self.name, "unit": self.unit, "minimum": self.minimum.tolist(),
                "channels": [{"values": g.tolist(), "rmse": r.tolist()}
                             for g, r in zip(self.grids, self.rmse)],
                "renders": self.renders, "samples_rendered": self.samples_rendered,
                "wall_s": round(self.wall_s, 3)}


def default_grid(spec, value: float, points: int) -> np.ndarray:
    """A grid around ``value`` that respects the parameter's bounds: a factor 4 either side for
    positive quantities bounded below, +-10 typical steps otherwise."""
    if np.isfinite(spec.lower) and not np.isfinite(spec.upper) and value > spec.lower:
        offset = value - spec.lower
        return spec.lower + offset * np.geomspace(0.25, 4.0, points)
    step = float(typical_step(spec, np.array([value]))[0])
    lo, hi = value - 10 * step, value + 10 * step
    if np.isfinite(spec.lower) and np.isfinite(spec.upper):  # e.g. IOR: a tenth either side
        lo, hi = max(spec.lower, value - 0.1), min(spec.upper, value + 0.1)
    return np.linspace(lo, hi, points)


def parabola_minimum(x: np.ndarray, y: np.ndarray) -> float:
    i = int(np.argmin(y))
    if i == 0 or i == len(x) - 1:
        return float(x[i])  # at the edge of the grid: no bracket
    a, b, c = np.polyfit(x[i - 1:i + 2], y[i - 1:i + 2], 2)
    return float(-b / (2 * a)) if a > 0 else float(x[i])


def scan(scene, capture, parameter: str, grid: np.ndarray | None = None, points: int = 15,
         spp: int = 16, downsample: int = 2, seed: int = 0, on_point=None,
         reweight: bool = True) -> ScanResult:
    """Scan ``parameter`` one channel at a time (see module docstring).

    Parameters
    ----------
    grid : ndarray, optional
        Values to scan (the same for each channel); default :func:`default_grid` per channel.
    downsample : int
        Compare images reduced by this factor (the seeds scan at low resolution).
    on_point : callable, optional
        Called after each grid point (progress).
    reweight : bool
        Take every grid point of a parameter that path-length recordings reweight (a glass
        absorption, the environment scale) from one recording per view, which is the same
        render at every value (:mod:`abs.render.path_lengths`); ``False``: render each point,
        as the seeds did.
    """
    t0 = time.perf_counter()
    model = build_model(scene, capture, [parameter], reweight=reweight)
    initial = model.compiled.get(parameter)
    spec = model.compiled.specs[parameter]
    problem = model.problem("train", downsample)
    grids = [np.asarray(grid, np.float64) if grid is not None else default_grid(spec, v, points)
             for v in initial]
    curves = channel_curves(problem, initial, grids, spp, seed, on_point)
    minima = [parabola_minimum(g, c) for g, c in zip(grids, curves)]
    return ScanResult(parameter, spec.unit, grids, curves, np.array(minima), model.counter.renders,
                      model.counter.samples, time.perf_counter() - t0)


def channel_curves(problem, theta: np.ndarray, grids: list[np.ndarray], spp: int, seed: int,
                   on_point=None, offset: int = 0) -> list[np.ndarray]:
    """RMSE of each colour channel as its scalar ``offset + c`` of ``theta`` steps through
    ``grids[c]``, everything else held at ``theta`` (one curve per grid; one grid: a scalar
    parameter scored on all channels).

    Residuals are stacked pixel by pixel with channels innermost, so channel ``c`` is
    ``r[c::3]``. Every point uses the seed ``seed`` (common random numbers: a smooth curve).
    """
    curves = []
    for c, values in enumerate(grids):
        curve = []
        for v in values:
            point = np.array(theta, np.float64)
            point[offset + c] = v
            r, _ = problem.residuals(point, spp, seed)
            channel = r[c::3] if len(grids) == 3 else r
            curve.append(float(np.sqrt(np.mean(channel ** 2))))
            if on_point is not None:
                on_point()
        curves.append(np.array(curve))
    return curves
