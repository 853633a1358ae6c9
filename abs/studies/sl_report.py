"""Figures, the HTML page and the published-tables section of the structured-light study (storage,
plotting and text only)."""

from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np

from abs.studies.sl_compare import compare_tables, convention_summary, markdown_comparison
from abs.studies.sl_paper import PaperTables
from abs.studies.sl_scanner import LUMINANCE, PROFILE_ANGLES_DEG, PROFILE_INCIDENCE_DEG
from abs.studies.sl_tables import markdown_table1, markdown_table2

__all__ = ["paper_markdown", "plot_profiles", "write_html"]

def _luminance(profile) -> np.ndarray:
    return LUMINANCE @ np.asarray(profile, float)


def plot_profiles(path: Path, material: str, results: dict[str, dict], tasks: list[dict]) -> Path:
    """The 45-degree in-plane profile of one material: truth, the error-free reconstruction, and
    each error type's levels (mean over repetitions ± 2 sd), as luminance, one panel per error type.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    own = [t for t in tasks if t["material"] == material]
    noises = list(dict.fromkeys(t["noise"] for t in own if t["noise"] is not None))
    clean = [t for t in own if t["noise"] is None]
    fig, axes = plt.subplots(1, max(len(noises), 1), figsize=(4.2 * max(len(noises), 1), 3.6),
                             sharey=True, squeeze=False)
    angles = PROFILE_ANGLES_DEG
    truth = None
    for t in own:
        if "profile_truth" in results.get(t["id"], {}):
            truth = _luminance(results[t["id"]]["profile_truth"])
            break
    reference = max(clean, key=lambda t: t["tessellation"]) if clean else None
    for ax, noise in zip(axes[0], noises or [None]):
        if truth is not None:
            ax.plot(angles, truth, "k-", lw=1.6, label="truth")
        if reference is not None and "profile_mean" in results.get(reference["id"], {}):
            ax.plot(angles, _luminance(results[reference["id"]]["profile_mean"]), "k--", lw=1.0,
                    label=f"no error (subdiv. {reference['tessellation']})")
        levels = sorted((t for t in own if t["noise"] == noise), key=lambda t: t["level"])
        colours = plt.cm.viridis(np.linspace(0.15, 0.85, max(len(levels), 1)))
        for t, colour in zip(levels, colours):
            r = results.get(t["id"], {})
            if "profile_luminance_mean" not in r:
                continue
            mean, sd = np.asarray(r["profile_luminance_mean"]), np.asarray(r["profile_luminance_sd"])
            ax.plot(angles, mean, color=colour, lw=1.0, label=f"σ = {t['level']:g}")
            ax.fill_between(angles, np.maximum(mean - 2 * sd, 1e-6), mean + 2 * sd, color=colour, alpha=0.2)
        ax.set_yscale("log")
        ax.set_xlabel("outgoing angle in the plane of incidence (deg)")
        ax.set_title(noise.replace("_", " ") if noise else material)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel(f"BRDF luminance (1/sr), θi = {PROFILE_INCIDENCE_DEG:g}°")
    fig.suptitle(f"{material}: in-plane profile (luminance, mean ± 2 sd over repetitions)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _markdown_to_html(markdown: str) -> str:
    rows = [line.strip().strip("|").split("|") for line in markdown.splitlines()
            if line.startswith("|") and not line.startswith("|---")]
    head = "".join(f"<th>{escape(c.strip())}</th>" for c in rows[0])
    body = "\n".join("<tr>" + "".join(f"<td>{escape(c.strip().replace('**', ''))}</td>" for c in r) + "</tr>"
                     for r in rows[1:])
    return f"<table><thead><tr>{head}</tr></thead><tbody>\n{body}\n</tbody></table>"


def paper_markdown(summary: dict, paper: PaperTables | None, missing: str | None = None) -> str:
    """The published tables beside abs's (Markdown), or, without them, a note saying why.

    Parameters
    ----------
    summary : dict
        ``study.json``.
    paper : PaperTables or None
        The published tables; None when the file was not found.
    missing : str, optional
        The file looked for, named in the note when ``paper`` is None.
    """
    if paper is None:
        return (f"The paper's published tables were not found (looked for {missing or 'no file'}); "
                "only abs's own tables are shown. They are in ../shared/docs/sl-study-paper-tables.md "
                "(see ../shared/README.md) or any file given with --paper-tables.")
    cells = compare_tables(summary, paper)
    summary_ = convention_summary(cells)
    t1, t2 = summary_["table1"], summary_["table2"]
    lines = [
        f"Published values from {paper.source}. Δ = abs − published; 'within 2 sd' is "
        "|Δ| ≤ 2 √(sd_published² + sd_abs²). Icosphere 5* (projector as the only light) has no abs "
        "counterpart: abs lights the sample with the scene light alone.",
        "",
        f"Cells compared: Table 1 {t1['compared']} of {t1['published']}, Table 2 {t2['compared']} of "
        f"{t2['published']}. Within 2 sd (per-pixel sds): {t1['within_pixel']} and {t2['within_pixel']}; "
        f"Table 2 with abs's sd over repetitions: {t2['within_repetition']} of {t2['error_cells']}. "
        f"abs higher than published in {t1['abs_higher'] + t2['abs_higher']} of "
        f"{t1['compared'] + t2['compared']}.",
        "",
        "Median sd / mean: published "
        f"{_ratio(summary_['paper_sd_over_mean'])}; abs, over pixels {_ratio(summary_['abs_pixel_sd_over_mean'])}, "
        f"over repetitions {_ratio(summary_['abs_repetition_sd_over_mean'])} (Table 2's error rows).",
        "",
        markdown_comparison(cells),
    ]
    return "\n".join(lines)


def _ratio(value: float | None) -> str:
    return "—" if value is None else f"{value:.2f}"


def _markdown_to_html_blocks(markdown: str) -> str:
    """Paragraphs and pipe tables of :func:`paper_markdown` as HTML."""
    html, table = [], []
    for line in markdown.splitlines() + [""]:
        if line.startswith("|"):
            table.append(line)
            continue
        if table:
            html.append(_markdown_to_html("\n".join(table)))
            table = []
        if line.strip():
            html.append(f"<p>{escape(line)}</p>")
    return "".join(html)


def write_html(path: Path, summary: dict, figures: list[Path], paper_text: str | None = None) -> Path:
    """``report.html``: settings, both tables, the published tables beside them (``paper_text``,
    from :func:`paper_markdown`), the profile figures (relative links)."""
    from abs.report.html import page, section

    config = summary["config"]
    settings = ", ".join(f"{k} = {escape(str(v))}" for k, v in config.items() if k != "noise")
    parts = [
        section("Settings", f"<p>{settings}</p><p>Runtime {summary['runtime_s']:.0f} s.</p>"),
        section("Table 1: no scanner error", "<p>CIEDE2000 between tone-mapped renderings of truth "
                "and reconstruction, mean ± sd over the sphere's pixels; the best Lambertian fit to "
                "the same samples as a baseline.</p>" + _markdown_to_html(markdown_table1(summary["table1"]))),
        section("Table 2: scanner errors", "<p>Mean over repetitions of the per-image mean CIEDE2000 "
                "± its sd over repetitions.</p>" + _markdown_to_html(markdown_table2(summary["table2"]))),
    ]
    if paper_text is not None:
        parts.append(section("The paper's published tables beside abs's", _markdown_to_html_blocks(paper_text)))
    parts.append(section("In-plane profiles", "".join(
        f'<figure><img src="{escape(f.name)}" alt="{escape(f.stem)}"></figure>' for f in figures)))
    path.write_text(page("Structured-light variational study", "\n".join(parts)))
    return path
