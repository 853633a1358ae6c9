"""The report's figures, each written as a PNG.

Built with matplotlib's object-oriented :class:`~matplotlib.figure.Figure` API, never pyplot:
no backend is selected, no GUI is touched, and a figure is freed as soon as it goes out of
scope instead of living on in pyplot's registry of open figures.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from abs.colour.tonemap import auto_exposure, tonemap
from abs.metrics import log_error
from abs.report.data import as_vector
from abs.report.view import ReportView

__all__ = ["save_figure", "error_limits", "plot_view", "plot_loss", "plot_traces", "plot_correlation"]

_ERROR_COLORMAP = "magma"
_DPI = 100
_PANEL_INCHES = 3.2  # width of one image panel


def save_figure(fig: Figure, path: Path) -> None:
    # "tight" keeps long rotated tick labels (correlation names) inside the image.
    fig.savefig(path, dpi=_DPI, bbox_inches="tight")


def _iteration_axis(ax: Axes) -> None:
    ax.set_xlabel("iteration")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))


def error_limits(views: Sequence[ReportView]) -> tuple[float, float]:
    """Colour limits for the log10 error images, shared by every view and by before/after.

    Parameters
    ----------
    views : sequence of ReportView
        All views of the report.

    Returns
    -------
    (float, float)
        ``(vmin, vmax)`` in log10 radiance units: the 1st percentile (so a few perfect pixels at
        the -6 floor do not stretch the scale) and the maximum of every error image.
    """
    errors = np.concatenate([log_error(image, v.photograph).ravel()
                             for v in views for image in (v.before, v.after)])
    vmin, vmax = float(np.percentile(errors, 1)), float(errors.max())
    return vmin, max(vmax, vmin + 1e-3)  # a flat scale would make the colour bar degenerate


def plot_view(path: Path, view: ReportView, limits: tuple[float, float]) -> None:
    """Photograph, rendering and log10 error image, before (top row) and after the fit (bottom).

    All three images of the view are tone-mapped with the photograph's exposure, so brightness
    differences are real; the error images share ``limits`` and one colour bar.

    Parameters
    ----------
    path : Path
        Destination PNG.
    view : ReportView
        The view to show.
    limits : (float, float)
        Colour limits of the error images, from :func:`error_limits`.
    """
    height, width = view.photograph.shape[:2]
    exposure = auto_exposure(view.photograph)
    fig = Figure(figsize=(3 * _PANEL_INCHES + 1.0, 2 * _PANEL_INCHES * height / width + 1.0),
                 layout="constrained")
    axes = fig.subplots(2, 3)
    kind = "holdout" if view.holdout else "train"
    fig.suptitle(f"{view.name} ({kind})")
    for row, (label, rendering) in enumerate((("initial", view.before), ("fitted", view.after))):
        axes[row, 0].imshow(tonemap(view.photograph, exposure), interpolation="nearest")
        axes[row, 0].set_title("photograph")
        axes[row, 1].imshow(tonemap(rendering, exposure), interpolation="nearest")
        axes[row, 1].set_title(f"rendering, {label}")
        errors = axes[row, 2].imshow(log_error(rendering, view.photograph), cmap=_ERROR_COLORMAP,
                                     vmin=limits[0], vmax=limits[1], interpolation="nearest")
        axes[row, 2].set_title(f"log10 error, {label}")
    for ax in axes.flat:
        ax.set_axis_off()
    fig.colorbar(errors, ax=axes[:, 2], label="log10 RGB error (radiance)", shrink=0.8)
    save_figure(fig, path)


def plot_loss(path: Path, iterations: np.ndarray, loss: np.ndarray) -> None:
    """Loss against iteration, on a log axis when every loss is positive.

    Parameters
    ----------
    path : Path
        Destination PNG.
    iterations, loss : np.ndarray
        Shape ``(n,)`` each, from :func:`abs.report.data.loss_curve`.
    """
    fig = Figure(figsize=(6.0, 3.5), layout="constrained")
    ax = fig.subplots()
    ax.plot(iterations, loss, marker="o", markersize=3)
    if np.all(loss > 0):  # a log axis would hide zero or negative losses
        ax.set_yscale("log")
    _iteration_axis(ax)
    ax.set_ylabel("loss")
    ax.grid(True, which="both", alpha=0.3)
    save_figure(fig, path)


def plot_traces(path: Path, traces: Mapping[str, tuple[np.ndarray, np.ndarray]],
                parameters: Mapping[str, Mapping]) -> None:
    """Each parameter's values against iteration, one panel per parameter.

    Components of a vector parameter are lines of one panel (labelled ``[i]``); a true value,
    where given, is a dashed line of the same colour.

    Parameters
    ----------
    path : Path
        Destination PNG.
    traces : mapping
        Name → ``(iterations, values)`` from :func:`abs.report.data.parameter_traces`; at least
        one parameter.
    parameters : mapping
        ``fit.json``'s ``parameters``: name → dict with optional ``unit`` and ``truth``.
    """
    columns = min(3, len(traces))
    rows = math.ceil(len(traces) / columns)
    fig = Figure(figsize=(4.0 * columns, 2.6 * rows + 0.4), layout="constrained")
    axes = fig.subplots(rows, columns, sharex=True, squeeze=False).ravel()
    for ax, (name, (iterations, values)) in zip(axes, traces.items()):
        info = parameters.get(name, {})
        truth = as_vector(info.get("truth"))
        vector = values.shape[1] > 1
        for i in range(values.shape[1]):
            (line,) = ax.plot(iterations, values[:, i], marker="o", markersize=2,
                              label=f"[{i}]" if vector else None)
            if i < truth.size and np.isfinite(truth[i]):
                ax.axhline(truth[i], color=line.get_color(), linestyle="--", linewidth=1)
        ax.set_title(name)
        ax.set_ylabel(info.get("unit") or "")
        _iteration_axis(ax)
        ax.grid(True, alpha=0.3)
        if vector:
            ax.legend(fontsize="small")
    for ax in axes[len(traces):]:
        ax.set_visible(False)
    save_figure(fig, path)


def plot_correlation(path: Path, names: Sequence[str], matrix: Sequence[Sequence[float]]) -> None:
    """Heat map of the parameters' correlation matrix, labelled, in [-1, 1].

    Parameters
    ----------
    path : Path
        Destination PNG.
    names : sequence of str
        One label per row/column, e.g. ``glass.absorption[0]``.
    matrix : array-like
        Square correlation matrix; ``None`` entries show as blank.
    """
    corr = np.stack([as_vector(row) for row in matrix])
    n = len(names)
    size = max(4.0, 0.45 * n + 2.5)
    fig = Figure(figsize=(size + 1.0, size), layout="constrained")
    ax = fig.subplots()
    image = ax.imshow(corr, cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    ax.set_xticks(range(n), names, rotation=90)
    ax.set_yticks(range(n), names)
    if n <= 16:  # beyond that the numbers no longer fit their cells
        for (i, j), c in np.ndenumerate(corr):
            if np.isfinite(c):
                ax.text(j, i, f"{c:.2f}", ha="center", va="center", fontsize="x-small",
                        color="white" if abs(c) > 0.6 else "black")
    fig.colorbar(image, ax=ax, label="correlation", shrink=0.8)
    save_figure(fig, path)


def plot_scan(path: Path, summary: Mapping, truth: Sequence[float] | None = None) -> None:
    """RMSE against the scanned value, one curve per colour channel, minima marked
    (``summary`` is ``scan.json``)."""
    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()
    channels = summary["channels"]
    colours = ["tab:red", "tab:green", "tab:blue"] if len(channels) == 3 else ["black"]
    for c, (entry, colour) in enumerate(zip(channels, colours)):
        label = f"channel {'RGB'[c]}" if len(channels) == 3 else summary["parameter"]
        ax.plot(entry["values"], entry["rmse"], "o-", color=colour, ms=3, label=label)
        ax.axvline(summary["minimum"][c], color=colour, lw=1, alpha=0.6)
        if truth is not None:
            ax.axvline(truth[c], color=colour, lw=1, ls="--", alpha=0.6)
    ax.set_xlabel(f"{summary['parameter']} ({summary['unit']})")
    ax.set_ylabel("RMSE of the channel (linear RGB)")
    ax.set_title("one-parameter scans (solid: minimum" + (", dashed: truth)" if truth else ")"))
    ax.legend()
    save_figure(fig, path)
