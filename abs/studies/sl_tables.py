"""The study's two tables from task results, in the layout of the paper's Tables 1 and 2.

- Table 1: CIEDE2000 (mean ± sd over the sphere's pixels) per material (rows) and tessellation
  (columns), without scanner errors; the best Lambertian fit to the same samples beside it.
- Table 2: CIEDE2000 per error type and level (rows) and material (columns): the mean over
  repetitions of the per-image mean, ± the sd of that mean over repetitions (the spread the
  random error causes); the per-pixel sd averaged over repetitions is kept in the JSON.
"""

from __future__ import annotations

import numpy as np

from abs.studies.sl_noise import NOISE_TYPES

__all__ = ["markdown_table1", "markdown_table2", "table1", "table2"]


def _finite(values) -> np.ndarray:
    return np.asarray([v for v in values if v is not None], float)


def table1(results: dict[str, dict], tasks: list[dict]) -> dict:
    """{material: {tessellation: {"mean", "sd", "samples", "lambert_mean", "lambert_sd"}}}."""
    out: dict = {}
    for task in tasks:
        if task["noise"] is not None:
            continue
        r = results[task["id"]]
        mean, sd = (r["delta_e_mean"][0], r["delta_e_sd"][0]) if r["delta_e_mean"] else (None, None)
        out.setdefault(task["material"], {})[str(task["tessellation"])] = {
            "mean": mean, "sd": sd, "samples": r["samples"][0],
            "lambert_mean": r.get("lambert_delta_e_mean"), "lambert_sd": r.get("lambert_delta_e_sd")}
    return out


def table2(results: dict[str, dict], tasks: list[dict]) -> dict:
    """{noise: {level: {material: {"mean", "sd", "pixel_sd", "repetitions", "samples_mean"}}}}."""
    out: dict = {}
    for task in tasks:
        if task["noise"] is None:
            continue
        r = results[task["id"]]
        means, pixel_sds = _finite(r["delta_e_mean"]), _finite(r["delta_e_sd"])
        out.setdefault(task["noise"], {}).setdefault(f"{task['level']:g}", {})[task["material"]] = {
            "mean": float(means.mean()) if means.size else None,
            "sd": float(means.std(ddof=1)) if means.size > 1 else None,
            "pixel_sd": float(pixel_sds.mean()) if pixel_sds.size else None,
            "repetitions": int(means.size),
            "samples_mean": float(np.mean(r["samples"])),
        }
    return out


def _pm(mean, sd) -> str:
    if mean is None:
        return "—"
    return f"{mean:.2f}" if sd is None else f"{mean:.2f} ± {sd:.2f}"


def markdown_table1(t1: dict) -> str:
    """Table 1 as Markdown: rows materials, columns tessellations (basis | Lambertian)."""
    tess = sorted({t for row in t1.values() for t in row}, key=int)
    head = "| material | " + " | ".join(f"subdiv. {t}" for t in tess) + " |"
    lines = [head, "|---" * (len(tess) + 1) + "|"]
    for material, row in t1.items():
        cells = [f"{_pm(row[t]['mean'], row[t]['sd'])} (Lambert {_pm(row[t]['lambert_mean'], row[t]['lambert_sd'])}, "
                 f"{row[t]['samples']} samples)" if t in row else "—" for t in tess]
        lines.append(f"| {material} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def markdown_table2(t2: dict) -> str:
    """Table 2 as Markdown: rows error type and level, columns materials."""
    materials = sorted({m for levels in t2.values() for row in levels.values() for m in row})
    lines = ["| error | σ | " + " | ".join(materials) + " |", "|---" * (len(materials) + 2) + "|"]
    for noise, levels in t2.items():
        unit = NOISE_TYPES[noise].unit if noise in NOISE_TYPES else ""
        for level, row in levels.items():
            cells = [_pm(row[m]["mean"], row[m]["sd"]) if m in row else "—" for m in materials]
            lines.append(f"| {noise.replace('_', ' ')} | {level} {unit} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
