"""A fit's folder: ``fit.json`` (public contract), the fitted scene, renderings and the report.

A fit folder holds::

    fit.json          the summary (docs/fitting.md, "Outputs")
    scene.toml        the fitted scene file (same format, fitted parameters replaced)
    checkpoint.json   the optimiser state after the last completed iteration (for --resume)
    renders/          EXR renderings of every view with the fitted parameters
    report/           report.html and its PNGs
"""

from __future__ import annotations

from pathlib import Path

from abs.io.images import write_exr
from abs.report import ReportView, write_fit_report
from abs.runs.files import write_json
from abs.scene.write import write_scene

__all__ = ["write_fit_folder", "FIT_FILE"]

FIT_FILE = "fit.json"


def write_fit_folder(folder: str | Path, scene, result, report: bool = True) -> dict:
    """Write a fit's outputs: ``fit.json``, the fitted ``scene.toml``, ``renders/*.exr`` and
    (unless ``report=False``) ``report/report.html``. Returns the summary (``fit.json``)."""
    folder = Path(folder)
    summary = result.summary()
    write_json(folder / FIT_FILE, summary)
    write_scene(scene, folder / "scene.toml", result.values)
    (folder / "renders").mkdir(parents=True, exist_ok=True)
    for view in result.views:
        write_exr(folder / "renders" / f"{view.name}.exr", view.after.astype("float32"))
    if report:
        views = [ReportView(v.name, v.holdout, v.photograph, v.before, v.after) for v in result.views]
        write_fit_report(folder / "report", summary, views, result.history)
    return summary
