"""The HTML report of a diagnosis: where the mismatch is, which effects were considered and why
the chosen one wins, and the holdout views before and after.

Plotting and HTML only; every number comes from the :class:`abs.diagnosis.Diagnosis`.
"""

from __future__ import annotations

import re
from html import escape
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from abs.colour.tonemap import auto_exposure, tonemap
from abs.metrics import log_error
from abs.report import figures, html
from abs.report.html import format_number, html_table
from abs.report.view import ReportView

__all__ = ["write_diagnosis_report", "plot_residual_map", "plot_candidates"]


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def plot_residual_map(path: Path, view, regions, photograph: np.ndarray, rendering: np.ndarray) -> None:
    """Photograph, baseline rendering and log10 error with the view's regions outlined."""
    h, w = photograph.shape[:2]
    exposure = auto_exposure(photograph)
    fig = Figure(figsize=(10.6, 3.2 * h / w + 0.9), layout="constrained")
    axes = fig.subplots(1, 3)
    axes[0].imshow(tonemap(photograph, exposure), interpolation="nearest")
    axes[0].set_title("photograph")
    axes[1].imshow(tonemap(rendering, exposure), interpolation="nearest")
    axes[1].set_title("baseline fit")
    image = axes[2].imshow(log_error(rendering, photograph), cmap="magma", interpolation="nearest")
    axes[2].set_title("log10 error, regions")
    for i, r in enumerate(regions):
        x0, y0, x1, y1 = r.bbox
        axes[2].add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False,
                                    edgecolor="cyan", linewidth=1.5))
        axes[2].text(x0, y0 - 1, f"{i + 1}: {100 * r.share_of_residual:.0f}%", color="cyan",
                     fontsize="small", va="bottom")
    for ax in axes:
        ax.set_axis_off()
    fig.colorbar(image, ax=axes[2], shrink=0.8, label="log10 RGB error")
    fig.suptitle(f"{view.name} ({'holdout' if view.holdout else 'train'})")
    fig.savefig(path, dpi=100, bbox_inches="tight")


def plot_candidates(path: Path, scores, accepted: set[str]) -> None:
    """Predicted BIC gain of every candidate of the first round (positive: worth a full fit)."""
    labels = [s.candidate.label for s in scores]
    gains = [s.predicted_bic_gain for s in scores]
    fig = Figure(figsize=(6.5, 0.45 * len(scores) + 1.2), layout="constrained")
    ax = fig.subplots()
    colours = ["tab:green" if s.candidate.label in accepted else
               ("tab:blue" if g > 0 else "tab:gray") for s, g in zip(scores, gains)]
    ax.barh(range(len(scores)), np.sign(gains) * np.log10(1 + np.abs(gains)), color=colours)
    ax.set_yticks(range(len(scores)), labels)
    ax.invert_yaxis()
    ax.axvline(0, color="black", linewidth=0.8)
    ax.set_xlabel("sign(g) log10(1 + |g|), g = score - dof ln M (predicted BIC gain)")
    ax.grid(True, axis="x", alpha=0.3)
    fig.savefig(path, dpi=100, bbox_inches="tight")


def _candidates_table(rounds) -> str:
    rows = []
    for i, r in enumerate(rounds):
        for s in r.scores:
            rows.append([str(i + 1), escape(s.candidate.label), escape(s.method), str(s.dof),
                         format_number(s.statistic, ".1f"), format_number(s.predicted_bic_gain, ".1f")])
    return html_table(["round", "candidate", "method", "dof", "score S", "predicted BIC gain"], rows)


def _trials_table(rounds) -> str:
    rows = []
    for i, r in enumerate(rounds):
        for s, trial, c in r.trials:
            rows.append([str(i + 1), escape(trial.label), format_number(c.holdout_rmse_before),
                         format_number(c.holdout_rmse_after), format_number(c.holdout_z, ".1f"),
                         format_number(c.delta_bic, ".1f"), "yes" if c.accepted else "no", escape(c.reason)])
    return html_table(["round", "model", "holdout RMSE, reference", "holdout RMSE, model", "holdout z",
                   "delta BIC", "accepted", "why"], rows)


def _compensation_table(findings) -> str:
    """Per finding, how the parameters fitted before its effect moved when it was added, in
    their standard errors (:mod:`abs.diagnosis.compensation`); flagged ones say so."""
    rows = []
    for f in findings:
        for s in f.compensation:
            z = s.in_stderr
            rows.append([escape(f.candidate.label), escape(s.parameter),
                         escape(", ".join(format_number(x) for x in s.before)),
                         escape(", ".join(format_number(x) for x in s.after)),
                         escape(", ".join(format_number(x) for x in s.stderr)),
                         escape(", ".join(format_number(x, "+.1f") for x in z)),
                         "<b>yes: compensating</b>" if s.compensating else "no"])
    if not rows:
        return ""
    return ("<p>How the parameters fitted without each effect moved when it was added, in the "
            "standard errors of the fit without it; a move beyond one standard error means the "
            "parameter was making up for the missing effect.</p>"
            + html_table(["finding", "parameter", "without the effect", "with it",
                          "standard error (without)", "move (standard errors)", "> 1 s.e."], rows))


def write_diagnosis_report(folder: str | Path, diagnosis) -> Path:
    """Write ``report.html`` and its PNGs into ``folder``; returns the HTML path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    verdict = diagnosis.verdict
    items = "".join(f"<li><b>{escape(f.candidate.effect)}</b> ({escape(f.candidate.target)}): "
                    f"{escape(f.explanation)}</li>" for f in diagnosis.findings)
    sections = [html.section("Verdict", f"<p>{'Missing: ' + escape(', '.join(verdict)) if verdict else 'Nothing missing: no effect of the catalogue improves the holdout views beyond noise.'}</p>"
                             + (f"<ul>{items}</ul>" if items else "")
                             + _compensation_table(diagnosis.findings)
                             + "".join(f"<p>{escape(n)}</p>" for n in diagnosis.notes))]

    final, base = diagnosis.final, diagnosis.baseline
    summary = {f"{split}_rmse": {"before": base.rmse(split), "after": final.rmse(split)}
               for split in ("train", "holdout")}
    summary.update({"method": final.result.method, "wall_s": diagnosis.wall_s})
    sections.append(html.section("Metrics (baseline fit, final model)", html.metrics_table(summary)))

    region_rows = [[str(i + 1), escape(r.view), escape(str(list(r.bbox))),
                    format_number(100 * r.share_of_residual, ".1f"), escape(r.where),
                    escape(", ".join(f"{x:+.3g}" for x in r.mean_residual))]
                   for i, r in enumerate(diagnosis.regions)]
    b = diagnosis.breakdown
    breakdown_rows = ([[escape(k), format_number(100 * v, ".1f")] for k, v in b["objects"].items()]
                      + [[f"ring {i + 1} of 4 (centre to corners)", format_number(100 * v, ".1f")]
                         for i, v in enumerate(b["radius_rings"])]
                      + [[f"channel {c}", format_number(100 * v, ".1f")] for c, v in zip("RGB", b["channels"])])
    figs = []
    photos = {v.name: v for v in base.result.views}
    for m in diagnosis.maps:
        v = photos[m.view]
        name = f"residual_{_safe(m.view)}.png"
        plot_residual_map(folder / name, v, [r for r in diagnosis.regions if r.view == m.view],
                          v.photograph, v.after)
        figs.append(html.figure(name, f"{m.view}: photograph, baseline fit, log10 error with the "
                                      "regions of concentrated residual"))
    sections.append(html.section(
        "Where the mismatch is",
        html_table(["region", "view", "bbox [x0, y0, x1, y1]", "share of residual (%)", "where",
                "mean rendering - photograph (R, G, B)"], region_rows),
        html_table(["squared residual by", "share (%)"], breakdown_rows),
        f"<p>Mean rendering - photograph per channel: "
        f"{escape(', '.join(f'{x:+.4g}' for x in b['mean_residual']))}.</p>", *figs))

    accepted = {f.candidate.label for f in diagnosis.findings}
    parts = [_candidates_table(diagnosis.rounds)]
    if diagnosis.candidates:
        plot_candidates(folder / "candidates.png", diagnosis.candidates, accepted)
        parts.append(html.figure("candidates.png", "first round: predicted BIC gain per candidate "
                                 "(green: accepted; blue: fitted fully; grey: not worth a fit)"))
    parts.append("<p>Candidates with a positive predicted BIC gain are fitted fully, next to a "
                 "control refit of the current model with the same fit settings (an effect fitted "
                 "at more samples or full resolution gets a control refitted so too); one is "
                 "accepted only if the holdout RMSE drops beyond noise and BIC prefers it.</p>" + _trials_table(diagnosis.rounds))
    sections.append(html.section("Candidates and why the winner wins", *parts))

    views = [ReportView(v.name, v.holdout, v.photograph, v.after,
                        {w.name: w.after for w in final.result.views}[v.name])
             for v in base.result.views if v.holdout]
    if views:
        limits = figures.error_limits(views)
        figs = []
        for v in views:
            name = f"holdout_{_safe(v.name)}.png"
            figures.plot_view(folder / name, v, limits)
            figs.append(html.figure(name, f"{v.name} (holdout): baseline fit (top) and final "
                                          f"model (bottom): photograph, rendering, log10 error"))
        sections.append(html.section("Holdout views before and after", *figs))
    path = folder / "report.html"
    path.write_text(html.page("Diagnosis report", *sections), encoding="utf-8")
    return path
