"""A fit's summary (``fit.json``) as lines of text for a terminal."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["summary_lines"]


def summary_lines(summary: Mapping) -> list[str]:
    """Where several starts went (when there were any), the difference steps a pilot chose (when
    one ran), where a polish moved a scalar (when one ran), ``name = [value ± stderr, ...] unit``
    per parameter, whether pixels were weighed by the capture's noise images, then RMSE before
    -> after."""
    lines = []
    starts = summary.get("starts")
    if starts:
        for k, tried in enumerate(starts["tried"]):
            start = ", ".join(f"{n} {v[0]:.4g}" for n, v in tried["start"].items())
            end = ", ".join(f"{np.ravel(tried['end'][n])[0]:.4g}" for n in tried["start"])
            chosen = "  <- chosen" if k == starts["chosen"] else ""
            lines.append(f"start {start} -> {end} (objective {tried['objective']:.4g}){chosen}")
    for name, chosen in (summary.get("difference_steps") or {}).items():
        tried = ", ".join(f"{t['step']:.3g}" for t in chosen["tried"])
        lines.append(f"difference step of {name}: {chosen['step']:.3g} (pilot of {tried})")
    for entry in summary.get("polish") or ():
        spread = entry["monte_carlo_stderr"]
        lines.append(f"polish of {entry['name']}[{entry['component']}]: {entry['start']:.6g} -> "
                     f"{entry['value']:.6g} (the objective's own minimum; "
                     f"{len(entry['vertices'])} seed pair(s) at {entry['spp']} spp"
                     + (f", Monte-Carlo ± {spread:.2g}" if spread is not None else "") + ")"
                     + (f": {entry['note']}" if entry["note"] else ""))
    for name, entry in summary["parameters"].items():
        values = ", ".join(f"{v:.5g} ± {s:.2g}" if s is not None else f"{v:.5g} (unconstrained)"
                           for v, s in zip(entry["value"], entry["stderr"]))
        lines.append(f"{name} = [{values}] {entry['unit']}")
    if summary.get("pixel_weights"):
        lines.append("pixels weighed by the capture's noise images (the RMSEs below are not)")
    for split in ("train", "holdout"):
        rmse = summary[f"{split}_rmse"]
        if rmse["before"] is not None:
            lines.append(f"{split} RMSE {rmse['before']:.4g} -> {rmse['after']:.4g}")
    return lines
