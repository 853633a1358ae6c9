"""Figures of the sampling report: corner plot, walker traces, posterior predictive images.

matplotlib's object-oriented API only (no pyplot), like :mod:`abs.report.figures`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from abs.colour.tonemap import auto_exposure, tonemap
from abs.report.figures import save_figure

__all__ = ["plot_corner", "plot_walker_traces", "plot_predictive"]


def plot_corner(path: Path, samples: np.ndarray, labels: Sequence[str],
                truth: np.ndarray | None = None, fit: np.ndarray | None = None) -> None:
    """Marginal histograms on the diagonal and pairwise 2-d histograms below it.

    Parameters
    ----------
    path : Path
        Destination PNG.
    samples : ndarray, shape (N, P)
        Posterior samples (physical units).
    labels : sequence of str
        One per column.
    truth, fit : ndarray, shape (P,), optional
        True values (dashed red) and the fit's values (dotted black); NaN entries are skipped.
    """
    p = samples.shape[1]
    size = max(2.2 * p, 3.0)
    fig = Figure(figsize=(size, size), layout="constrained")
    axes = fig.subplots(p, p, squeeze=False)
    q = np.quantile(samples, [0.05, 0.5, 0.95], axis=0)
    for i in range(p):
        for j in range(p):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(samples[:, i], bins=30, color="tab:blue", histtype="stepfilled", alpha=0.6)
                for v in q[:, i]:
                    ax.axvline(v, color="tab:blue", lw=0.8, ls="-")
                ax.set_yticks([])
                ax.set_title(f"{labels[i]}\n{q[1, i]:.4g} [{q[0, i]:.4g}, {q[2, i]:.4g}]",
                             fontsize="small")
            else:
                ax.hist2d(samples[:, j], samples[:, i], bins=30, cmap="Blues")
            for values, style in ((truth, dict(color="tab:red", ls="--")),
                                  (fit, dict(color="black", ls=":"))):
                if values is None:
                    continue
                if np.isfinite(values[j]):
                    ax.axvline(values[j], lw=1, **style)
                if i != j and np.isfinite(values[i]):
                    ax.axhline(values[i], lw=1, **style)
            if i == p - 1:
                ax.set_xlabel(labels[j], fontsize="small")
            if j == 0 and i > 0:
                ax.set_ylabel(labels[i], fontsize="small")
    save_figure(fig, path)


def plot_walker_traces(path: Path, chain: np.ndarray, labels: Sequence[str], burn_in: int) -> None:
    """Every walker's value against step, one panel per scalar; the burn-in is shaded.

    Parameters
    ----------
    chain : ndarray, shape (S, W, P)
        The whole chain, burn-in included.
    """
    p = chain.shape[2]
    fig = Figure(figsize=(7.0, 1.8 * p + 0.6), layout="constrained")
    axes = fig.subplots(p, 1, sharex=True, squeeze=False)[:, 0]
    for k, ax in enumerate(axes):
        ax.plot(chain[:, :, k], color="black", alpha=0.3, lw=0.6)
        ax.axvspan(0, burn_in, color="tab:orange", alpha=0.15, lw=0)
        ax.set_ylabel(labels[k], fontsize="small")
    axes[-1].set_xlabel("step (shaded: burn-in)")
    save_figure(fig, path)


def plot_predictive(path: Path, name: str, holdout: bool, photograph: np.ndarray,
                    mean: np.ndarray, sd: np.ndarray) -> None:
    """Photograph, posterior predictive mean rendering, and per-pixel sd (mean over RGB)."""
    height, width = photograph.shape[:2]
    exposure = auto_exposure(photograph)
    fig = Figure(figsize=(10.6, 3.2 * height / width + 0.9), layout="constrained")
    axes = fig.subplots(1, 3)
    fig.suptitle(f"{name} ({'holdout' if holdout else 'train'})")
    axes[0].imshow(tonemap(photograph, exposure), interpolation="nearest")
    axes[0].set_title("photograph")
    axes[1].imshow(tonemap(mean, exposure), interpolation="nearest")
    axes[1].set_title("posterior mean rendering")
    spread = axes[2].imshow(sd.mean(axis=-1), cmap="viridis", interpolation="nearest")
    axes[2].set_title("per-pixel sd over draws")
    for ax in axes:
        ax.set_axis_off()
    fig.colorbar(spread, ax=axes[2], label="radiance sd", shrink=0.8)
    save_figure(fig, path)
