"""Write the HTML report of a fit: tables, convergence plots and per-view comparisons."""

from __future__ import annotations

import re
from html import escape
from collections.abc import Mapping, Sequence
from pathlib import Path

from abs.metrics import rmse
from abs.report import figures, html
from abs.report.data import loss_curve, parameter_traces
from abs.report.view import ReportView

__all__ = ["write_fit_report"]


def _file_name(index: int, name: str) -> str:
    # The index keeps names unique even when sanitising maps two view names to the same string.
    return f"view_{index:02d}_{re.sub(r'[^A-Za-z0-9_.-]+', '_', name)}.png"


def write_fit_report(folder: str | Path, summary: Mapping, views: Sequence[ReportView],
                     history: Sequence[Mapping]) -> Path:
    """Write ``report.html`` and its PNG figures into ``folder``.

    Parameters
    ----------
    folder : str or Path
        Output folder, created if needed; existing report files in it are overwritten.
    summary : mapping
        Content of ``fit.json``: ``parameters`` (name → ``value``, optional ``stderr``,
        ``unit``, ``initial``, ``truth``), and optionally ``correlation`` (``names``,
        ``matrix``), ``train_rmse``/``holdout_rmse``/``train_ssim``/``holdout_ssim``
        (``{"before": x, "after": y}``), ``renders``, ``samples_rendered``, ``wall_s``,
        ``iterations``, ``method``.
    views : sequence of ReportView
        Photographs with their renderings before and after the fit; training views are shown
        first, then holdout views.
    history : sequence of dict
        Per-iteration records ``{"iteration": i, "loss": x, "values": {name: value}}``; may
        be empty, in which case the convergence plots are left out.

    Returns
    -------
    Path
        Path of ``report.html``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    parameters = summary.get("parameters", {})
    checks = summary.get("checks") or []
    # What the fit's own numbers say went wrong comes first (abs.fitting.checks).
    sections = ([html.section("Checks", *(f"<p>{escape(c)}</p>" for c in checks))] if checks else [])
    sections += [html.section("Metrics", html.metrics_table(summary)),
                 html.section("Parameters", html.parameter_table(parameters))]
    if summary.get("starts"):
        sections.append(html.section("Several starts", html.starts_table(summary["starts"])))

    convergence = []
    iterations, loss = loss_curve(history)
    if loss.size:
        figures.plot_loss(folder / "loss.png", iterations, loss)
        convergence.append(html.figure("loss.png", "loss against iteration"))
    traces = parameter_traces(history, list(parameters))
    if traces:
        figures.plot_traces(folder / "parameters.png", traces, parameters)
        convergence.append(html.figure("parameters.png", "parameter values against iteration "
                                                         "(dashed: true values)"))
    if convergence:
        sections.append(html.section("Convergence", *convergence))

    scan = summary.get("scan")
    if scan:
        truth = parameters.get(scan["parameter"], {}).get("truth")
        figures.plot_scan(folder / "scan.png", scan, truth)
        sections.append(html.section("Scan", html.figure(
            "scan.png", f"the seeds' per-channel scan of {scan['parameter']} around the fit, "
                        "reweighted from the fit's own path-length recordings (no renders)")))

    correlation = summary.get("correlation") or {}
    if correlation.get("names"):
        figures.plot_correlation(folder / "correlation.png", correlation["names"],
                                 correlation["matrix"])
        sections.append(html.section("Correlation", html.figure(
            "correlation.png", "correlation matrix of the fitted parameters")))

    if views:
        limits = figures.error_limits(views)
        ordered = sorted(enumerate(views), key=lambda item: item[1].holdout)  # stable: train first
        parts = []
        for index, view in ordered:
            name = _file_name(index, view.name)
            figures.plot_view(folder / name, view, limits)
            parts.append(html.view_section(view.name, view.holdout, name,
                                           rmse(view.before, view.photograph),
                                           rmse(view.after, view.photograph)))
        sections.append(html.section("Views", *parts))

    path = folder / "report.html"
    path.write_text(html.page("Fit report", *sections), encoding="utf-8")
    return path
