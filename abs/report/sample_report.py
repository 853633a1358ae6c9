"""Write the HTML report of a posterior sampling run (``abs sample``)."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from html import escape
from pathlib import Path

import numpy as np

from abs.report import html, sampling_figures
from abs.report.data import as_vector

__all__ = ["write_sample_report", "posterior_table"]


def posterior_table(summary: Mapping) -> str:
    """One row per scalar: mean, sd, 5-95 % interval, ESS, tau, R-hat, fit ± stderr, truth."""
    header = ["parameter", "unit", "mean", "sd", "5 %", "95 %", "ESS", "tau (steps)", "R-hat",
              "fit ± stderr", "truth"]
    rows = []
    for name, e in summary["parameters"].items():
        n = len(e["mean"])
        cols = {k: np.broadcast_to(as_vector(e.get(k)), (n,))
                for k in ("mean", "sd", "q05", "q95", "ess", "tau", "r_hat", "truth")}
        fit = e.get("fit") or {}
        value, stderr = (np.broadcast_to(as_vector(fit.get(k)), (n,)) for k in ("value", "stderr"))
        for i in range(n):
            fitted = html.format_number(value[i])
            if np.isfinite(stderr[i]):
                fitted += f" ± {html.format_number(stderr[i], '.2g')}"
            rows.append([escape(name if n == 1 else f"{name}[{i}]"), escape(e.get("unit") or ""),
                         html.format_number(cols["mean"][i]), html.format_number(cols["sd"][i], ".3g"),
                         html.format_number(cols["q05"][i]), html.format_number(cols["q95"][i]),
                         html.format_number(cols["ess"][i], ".0f"), html.format_number(cols["tau"][i], ".3g"),
                         html.format_number(cols["r_hat"][i], ".3f"), fitted,
                         html.format_number(cols["truth"][i])])
    return html.html_table(header, rows)


def _run_table(summary: Mapping) -> str:
    keys = ("walkers", "steps", "burn_in", "samples", "acceptance_fraction", "converged",
            "stop_reason", "evaluations", "renders", "wall_s", "spp", "downsample")
    rows = [[escape(k.replace("_", " ")), escape(str(summary.get(k)))] for k in keys]
    noise = summary.get("noise") or {}
    rows += [[escape(f"noise: {k.replace('_', ' ')}"), escape(str(v))] for k, v in noise.items()]
    return html.html_table(["run", ""], rows)


def write_sample_report(folder: str | Path, summary: Mapping, chain: np.ndarray,
                        kept: np.ndarray, predictive: Sequence) -> Path:
    """Write ``report.html`` with tables, corner plot, walker traces and predictive images.

    Parameters
    ----------
    summary : mapping
        ``summary.json``.
    chain : ndarray, shape (S, W, P)
        The whole chain (for the traces).
    kept : ndarray, shape (S', W, P)
        The chain after burn-in (for the corner plot).
    predictive : sequence of PredictiveView
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    labels = summary["labels"]
    params = summary["parameters"]
    stack = lambda key, sub=None: np.concatenate([  # noqa: E731
        np.broadcast_to(as_vector((e.get(sub) or {}).get(key) if sub else e.get(key)),
                        (len(e["mean"]),)) for e in params.values()])
    checks = summary.get("checks") or []
    sections = ([html.section("Checks", *(f"<p>{escape(c)}</p>" for c in checks))] if checks else [])
    sections += [html.section("Posterior", posterior_table(summary)),
                html.section("Run", _run_table(summary))]
    flat = kept.reshape(-1, kept.shape[-1])
    if flat.shape[0] > 1:
        sampling_figures.plot_corner(folder / "corner.png", flat, labels, stack("truth"),
                                     stack("value", "fit"))
        sections.append(html.section("Corner plot", html.figure(
            "corner.png", "posterior marginals and pairs (solid: 5/50/95 %; dashed red: truth; "
                          "dotted: fit)")))
    if chain.shape[0] > 0:
        sampling_figures.plot_walker_traces(folder / "traces.png", chain, labels,
                                            summary.get("burn_in", 0))
        sections.append(html.section("Walkers", html.figure("traces.png", "walker traces")))
    parts = []
    for index, view in enumerate(sorted(predictive, key=lambda v: v.holdout)):
        name = f"predictive_{index:02d}_{re.sub(r'[^A-Za-z0-9_.-]+', '_', view.name)}.png"
        sampling_figures.plot_predictive(folder / name, view.name, view.holdout, view.photograph,
                                         view.mean, view.sd)
        parts.append(html.figure(name, f"{view.name}: photograph, posterior predictive mean, "
                                       "per-pixel sd over posterior draws (same seed)"))
    if parts:
        sections.append(html.section("Posterior predictive", *parts))
    path = folder / "report.html"
    path.write_text(html.page("Sampling report", *sections), encoding="utf-8")
    return path
