"""A fit's summary (``fit.json``) as lines of text for a terminal."""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["summary_lines"]


def summary_lines(summary: Mapping) -> list[str]:
    """``name = [value ± stderr, ...] unit`` per parameter, then RMSE before -> after."""
    lines = []
    for name, entry in summary["parameters"].items():
        values = ", ".join(f"{v:.5g} ± {s:.2g}" if s is not None else f"{v:.5g} (unconstrained)"
                           for v, s in zip(entry["value"], entry["stderr"]))
        lines.append(f"{name} = [{values}] {entry['unit']}")
    for split in ("train", "holdout"):
        rmse = summary[f"{split}_rmse"]
        if rmse["before"] is not None:
            lines.append(f"{split} RMSE {rmse['before']:.4g} -> {rmse['after']:.4g}")
    return lines
