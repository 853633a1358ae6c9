"""Report figures for calibration and HDR merging (PNG files; no algorithm lives here)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

__all__ = ["write_coverage_png", "write_detection_png", "write_view_rms_png",
           "write_weight_png", "write_noise_png"]


def write_coverage_png(path: Path, counts: np.ndarray) -> None:
    """Board coverage: how many views' board outlines cover each pixel (black = none)."""
    scaled = np.clip(counts * (255.0 / max(int(counts.max()), 1)), 0, 255).astype(np.uint8)
    colour = cv2.applyColorMap(scaled, cv2.COLORMAP_VIRIDIS)
    colour[counts == 0] = 0
    cv2.imwrite(str(path), colour)


def write_detection_png(path: Path, gray: np.ndarray, corners: np.ndarray | None,
                        pattern: tuple[int, int]) -> None:
    """The image with its detected corners drawn.

    A whole board is drawn as OpenCV's ``drawChessboardCorners`` draws it (``pattern``: inner
    corners per row and column); a partial one (NaN rows, a ChArUco board) as its seen corners,
    each labelled with its id.
    """
    bgr = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    if corners is not None:
        corners = np.asarray(corners, np.float32).reshape(-1, 2)
        seen = np.all(np.isfinite(corners), axis=1)
        if seen.all():
            cv2.drawChessboardCorners(bgr, pattern, corners.reshape(-1, 1, 2), True)
        else:
            ids = np.flatnonzero(seen).astype(np.int32).reshape(-1, 1)
            cv2.aruco.drawDetectedCornersCharuco(bgr, corners[seen].reshape(-1, 1, 2), ids)
    cv2.imwrite(str(path), bgr)


def write_view_rms_png(path: Path, names: Sequence[str], rms_px: np.ndarray,
                       outliers: Sequence[str]) -> None:
    """Bar chart of the RMS reprojection error per view, outliers in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(4.0, 0.3 * len(names)), 3.0))
    colours = ["tab:red" if n in outliers else "tab:blue" for n in names]
    ax.bar(range(len(names)), rms_px, color=colours)
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=6)
    ax.set_ylabel("RMS reprojection error (px)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_weight_png(path: Path, weight_s: np.ndarray) -> None:
    """HDR weight map: total exposure time used per pixel (white = every frame, black = none)."""
    w = weight_s if weight_s.ndim == 2 else weight_s.mean(axis=-1)
    scaled = np.clip(w / max(float(w.max()), 1e-30) * 255.0, 0, 255).astype(np.uint8)
    cv2.imwrite(str(path), scaled)


def write_noise_png(path: Path, image: np.ndarray, noise_sd: np.ndarray) -> None:
    """A built photograph's noise relative to its value (channels averaged), log scale with a
    colour bar in per cent: where the merged brackets are quiet (near full well in some frame)
    and where they are not (dark pixels, frames' edges)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import FuncFormatter

    value = np.maximum(np.asarray(image, np.float64).mean(axis=-1), 1e-30)
    relative = 100.0 * np.asarray(noise_sd, np.float64).mean(axis=-1) / value
    relative = np.clip(relative, 1e-3, 1e3)
    height, width = relative.shape
    fig, ax = plt.subplots(figsize=(4.0 + 2.0, 4.0 * height / max(width, 1) + 0.4))
    shown = ax.imshow(relative, cmap="magma", norm=LogNorm(vmin=max(relative.min(), 1e-2),
                                                            vmax=max(relative.max(), 1e-1)))
    ax.set_axis_off()
    bar = fig.colorbar(shown, ax=ax, label="noise / value (%)")
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    bar.ax.yaxis.set_major_formatter(plain)
    bar.ax.yaxis.set_minor_formatter(plain)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
