"""Figures and the HTML page of the structured-light study (storage and plotting only)."""

from __future__ import annotations

from html import escape
from pathlib import Path

import numpy as np

from abs.studies.sl_scanner import LUMINANCE, PROFILE_ANGLES_DEG, PROFILE_INCIDENCE_DEG
from abs.studies.sl_tables import markdown_table1, markdown_table2

__all__ = ["plot_profiles", "write_html"]

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
    rows = [line.strip().strip("|").split("|") for line in markdown.splitlines() if not line.startswith("|---")]
    head = "".join(f"<th>{escape(c.strip())}</th>" for c in rows[0])
    body = "\n".join("<tr>" + "".join(f"<td>{escape(c.strip())}</td>" for c in r) + "</tr>" for r in rows[1:])
    return f"<table><thead><tr>{head}</tr></thead><tbody>\n{body}\n</tbody></table>"


def write_html(path: Path, summary: dict, figures: list[Path]) -> Path:
    """``report.html``: settings, both tables, the profile figures (relative links)."""
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
        section("In-plane profiles", "".join(
            f'<figure><img src="{escape(f.name)}" alt="{escape(f.stem)}"></figure>' for f in figures)),
    ]
    path.write_text(page("Structured-light variational study", "\n".join(parts)))
    return path
