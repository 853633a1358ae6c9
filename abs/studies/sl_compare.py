"""abs's study tables beside the paper's published ones, cell by cell.

Every published cell (:mod:`abs.studies.sl_paper`) is paired with abs's cell of the same table,
row and material (``study.json``'s ``table1``/``table2``; the paper's "Ideal" row of Table 2 with
abs's error-free subdivision of the error study). For each pair: the difference
Δ = abs − paper (CIEDE2000 units) and whether it lies within two standard deviations of the two
values combined, |Δ| ≤ 2 √(sd_paper² + sd_abs²).

Which sd is "the" sd matters. The paper's ± reads as the spread over the sphere's *pixels*: its
error-free Table 1, which has no random scanner error to repeat, has sds as large as its means.
So the comparison uses abs's per-pixel sd (Table 1's sd, Table 2's ``pixel_sd``). For Table 2 the
verdict is also given for the other reading (both ± over the 30 repetitions; abs's ``sd``):
:func:`convention_summary` measures which reading the published numbers fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from abs.studies.sl_noise import NOISE_TYPES
from abs.studies.sl_paper import PaperTables

__all__ = ["CellComparison", "compare_tables", "convention_summary", "markdown_comparison"]


@dataclass(frozen=True)
class CellComparison:
    """One published cell beside abs's (CIEDE2000; abs values None where abs has no such cell).

    Attributes
    ----------
    table : str
        "1" or "2".
    row : str
        The row in the paper's words, e.g. "icosphere 5*", "vertex position 3 mm", "ideal".
    material : str
        The column.
    paper_mean, paper_sd : float
        Published mean ± sd.
    abs_mean, abs_pixel_sd : float or None
        abs's mean and its sd over the sphere's pixels (averaged over repetitions in Table 2).
    abs_repetition_sd : float or None
        abs's sd of the per-image mean over repetitions (Table 2's error rows only).
    paper_ideal, abs_ideal : float or None
        The error-free mean of the same material (Table 2's error rows only): the rise over it
        compares how much an error costs, apart from the two error-free floors.
    """

    table: str
    row: str
    material: str
    paper_mean: float
    paper_sd: float
    abs_mean: float | None
    abs_pixel_sd: float | None
    abs_repetition_sd: float | None = None
    paper_ideal: float | None = None
    abs_ideal: float | None = None

    @property
    def paper_rise(self) -> float | None:
        """Published mean − published error-free mean."""
        return None if self.paper_ideal is None else self.paper_mean - self.paper_ideal

    @property
    def abs_rise(self) -> float | None:
        """abs's mean − abs's error-free mean."""
        return None if self.abs_ideal is None or self.abs_mean is None else self.abs_mean - self.abs_ideal

    @property
    def difference(self) -> float | None:
        """Δ = abs − paper."""
        return None if self.abs_mean is None else self.abs_mean - self.paper_mean

    def _within(self, abs_sd: float | None) -> bool | None:
        if self.abs_mean is None or abs_sd is None:
            return None
        return abs(self.difference) <= 2.0 * float(np.hypot(self.paper_sd, abs_sd))

    @property
    def within_2sd(self) -> bool | None:
        """|Δ| ≤ 2 √(sd_paper² + sd_abs²) with abs's per-pixel sd (the paper's ± read as per pixel)."""
        return self._within(self.abs_pixel_sd)

    @property
    def within_2sd_repetitions(self) -> bool | None:
        """The same with abs's sd over repetitions (the paper's ± read as over repetitions)."""
        return self._within(self.abs_repetition_sd)


def _get(mapping: dict, *keys):
    for key in keys:
        if not isinstance(mapping, dict) or key not in mapping:
            return None
        mapping = mapping[key]
    return mapping


def compare_tables(summary: dict, paper: PaperTables) -> list[CellComparison]:
    """Pair every published cell with abs's (see the module docstring).

    Parameters
    ----------
    summary : dict
        ``study.json``: its ``table1``, ``table2`` and ``config.noise_tessellation``.
    paper : PaperTables
        The published tables.

    Returns
    -------
    list of CellComparison
        Table 1 (paper rows × materials), then Table 2's ideal row and error rows.
    """
    ours1, ours2 = summary.get("table1", {}), summary.get("table2", {})
    out = []
    for material, rows in paper.table1.items():
        for row, cell in rows.items():
            # "5*" (projector as the only light) has no abs counterpart: abs lights with the scene light.
            own = _get(ours1, material, row)
            out.append(CellComparison("1", f"icosphere {row}", material, cell["mean"], cell["sd"],
                                      _get(own, "mean"), _get(own, "sd")))
    tess = str(summary.get("config", {}).get("noise_tessellation", 5))
    for material, cell in paper.ideal.items():
        own = _get(ours1, material, tess)
        out.append(CellComparison("2", "ideal", material, cell["mean"], cell["sd"],
                                  _get(own, "mean"), _get(own, "sd")))
    for noise, levels in paper.table2.items():
        unit = NOISE_TYPES[noise].unit
        for level, row in levels.items():
            for material, cell in row.items():
                own = _get(ours2, noise, level, material)
                out.append(CellComparison("2", f"{noise.replace('_', ' ')} {level} {unit}", material,
                                          cell["mean"], cell["sd"], _get(own, "mean"),
                                          _get(own, "pixel_sd"), _get(own, "sd"),
                                          _get(paper.ideal, material, "mean"),
                                          _get(ours1, material, tess, "mean")))
    return out


def convention_summary(cells: list[CellComparison]) -> dict:
    """How the ± conventions compare, over the cells abs has (medians of sd / mean).

    Returns
    -------
    dict
        ``paper_sd_over_mean`` (all published cells), ``abs_pixel_sd_over_mean`` and
        ``abs_repetition_sd_over_mean`` (Table 2's error rows), and per table the number of cells
        compared and within 2 sd under each reading (``within_pixel``, ``within_repetition``).
    """
    paired = [c for c in cells if c.abs_mean is not None]
    errors = [c for c in paired if c.abs_repetition_sd is not None]

    def median(values) -> float | None:
        values = [v for v in values if v is not None and np.isfinite(v)]
        return float(np.median(values)) if values else None

    out: dict = {
        "paper_sd_over_mean": median(c.paper_sd / c.paper_mean for c in cells if c.paper_mean > 0),
        "abs_pixel_sd_over_mean": median(c.abs_pixel_sd / c.abs_mean for c in errors if c.abs_mean > 0),
        "abs_repetition_sd_over_mean": median(c.abs_repetition_sd / c.abs_mean for c in errors
                                              if c.abs_mean > 0),
    }
    for table in ("1", "2"):
        own = [c for c in paired if c.table == table]
        out[f"table{table}"] = {
            "published": sum(c.table == table for c in cells), "compared": len(own),
            "within_pixel": sum(bool(c.within_2sd) for c in own),
            "within_repetition": sum(bool(c.within_2sd_repetitions) for c in own
                                     if c.abs_repetition_sd is not None),
            "error_cells": sum(c.abs_repetition_sd is not None for c in own),
            "abs_higher": sum(c.difference > 0 for c in own),
        }
    return out


def _number(value: float | None, spec: str = ".2f") -> str:
    return "—" if value is None else format(value, spec)


def _pm(mean: float | None, sd: float | None) -> str:
    return "—" if mean is None else f"{mean:.2f} ± {_number(sd)}"


def _verdict(within: bool | None) -> str:
    return "—" if within is None else ("yes" if within else "**no**")


def markdown_comparison(cells: list[CellComparison]) -> str:
    """Both tables, one line per published cell: published, abs, Δ, within 2 sd; in Table 2 also
    abs's sd over repetitions and the verdict with it, and each side's rise over its error-free
    mean (Markdown)."""
    parts = []
    for table, title in (("1", "Table 1 (no scanner error)"), ("2", "Table 2 (icosphere 5, scanner errors)")):
        own = [c for c in cells if c.table == table]
        if not own:
            continue
        repetitions = table == "2"
        head = ["row", "material", "published", "abs (± per pixel)", "Δ = abs − published",
                "within 2 sd (per pixel)"]
        if repetitions:
            head[4:4] = ["abs sd over repetitions"]
            head += ["within 2 sd (per repetition)", "rise over ideal: published / abs"]
        lines = [f"{title}:", "", "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
        for c in own:
            row = [c.row, c.material, _pm(c.paper_mean, c.paper_sd), _pm(c.abs_mean, c.abs_pixel_sd),
                   _number(c.difference, "+.2f"), _verdict(c.within_2sd)]
            if repetitions:
                row[4:4] = [_number(c.abs_repetition_sd)]
                row += [_verdict(c.within_2sd_repetitions),
                        f"{_number(c.paper_rise, '+.2f')} / {_number(c.abs_rise, '+.2f')}"
                        if c.paper_rise is not None else "—"]
            lines.append("| " + " | ".join(row) + " |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts)
