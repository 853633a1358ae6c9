"""The seed paper's published Tables 1 and 2, read from a Markdown file into the study's layout.

The file (``../shared/docs/sl-study-paper-tables.md``; not in the repository) holds the paper's
two tables as Markdown pipe tables, each under a level-2 heading starting ``## Table 1`` or
``## Table 2``, every value written ``mean ± sd`` (CIEDE2000). They are read into the layout of
:mod:`abs.studies.sl_tables`, so that a cell of the paper and the same cell of abs have the same
keys:

- ``table1[material][row]``: ``row`` is the icosphere subdivision as a string (``"1"``, ``"3"``,
  ``"5"``), or ``"5*"`` for the paper's projector-only row (abs has no counterpart);
- ``table2[noise][level][material]``: ``noise`` a name of
  :data:`~abs.studies.sl_noise.NOISE_TYPES`, ``level`` its σ in that type's unit written as abs
  writes it (``f"{level:g}"``);
- ``ideal[material]``: Table 2's error-free row (the paper's subdivision 5 without error).

Each cell is ``{"mean": float, "sd": float}``. A malformed table is an
:class:`~abs.errors.InputError` naming the file and the line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from abs.errors import InputError
from abs.io.shared_data import shared_data_dir
from abs.studies.sl_noise import NOISE_TYPES

__all__ = ["PAPER_NOISE_NAMES", "PaperTables", "default_paper_tables_path", "parse_paper_tables",
           "read_paper_tables"]

PAPER_NOISE_NAMES: dict[str, str] = {
    "vertex position": "vertex_position",
    "normal (polar tilt)": "normal_tilt",
    "normal tilt": "normal_tilt",
    "light position": "light_position",
    "light intensity": "light_intensity",
}
"""The paper's names of the error types (lower case) -> abs's names in NOISE_TYPES."""

_UNITS = {"°": "deg", "deg": "deg", "mm": "mm", "%": "%"}
_CELL = re.compile(r"^(-?\d+(?:\.\d+)?)\s*(?:±|\+-|\+/-)\s*(\d+(?:\.\d+)?)$")
_LEVEL = re.compile(r"^(\d+(?:\.\d+)?)\s*(°|deg|mm|%)$")
_ICOSPHERE = re.compile(r"^icosphere\s+(\d+)(\*?)$", re.IGNORECASE)
_SEPARATOR = re.compile(r"^\|(\s*:?-+:?\s*\|)+$")


@dataclass(frozen=True)
class PaperTables:
    """The paper's tables in the study's layout (see the module docstring).

    Attributes
    ----------
    source : str
        The file they were read from.
    table1 : dict
        {material: {row: {"mean", "sd"}}}, rows "1", "3", "5" (two lights) and "5*" (projector only).
    table2 : dict
        {noise: {level: {material: {"mean", "sd"}}}}.
    ideal : dict
        {material: {"mean", "sd"}}, Table 2's error-free row.
    """

    source: str
    table1: dict
    table2: dict
    ideal: dict


def default_paper_tables_path() -> Path:
    """``../shared/docs/sl-study-paper-tables.md`` (beside the shared data folder); may not exist."""
    return shared_data_dir().parent / "docs" / "sl-study-paper-tables.md"


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _tables_by_heading(text: str, source: str) -> dict[str, list[tuple[int, list[str]]]]:
    """{"1": [(line number, cells), ...], "2": ...}: the first pipe table under each
    ``## Table N`` heading (header first, separator dropped)."""
    found: dict[str, list[tuple[int, list[str]]]] = {}
    current: str | None = None
    separated = False
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped.startswith("#"):
            match = re.match(r"^##\s+table\s+(\d+)\b", stripped, re.IGNORECASE)
            current = match.group(1) if match else None
            if current in found:
                raise InputError(source, f"line {number}", f"a second heading for Table {current}")
            separated = False
            continue
        if current is None:
            continue
        if not stripped.startswith("|"):
            if current in found:
                current = None  # the table has ended; anything after it is not read
            continue
        rows = found.setdefault(current, [])
        if rows and not separated:
            if not _SEPARATOR.match(stripped.replace(" ", "")):
                raise InputError(source, f"line {number}", "expected the header separator row "
                                                           "(|---|---|...) after the table's header")
            separated = True
            continue
        rows.append((number, _cells(stripped)))
    for key in ("1", "2"):
        if key not in found or len(found[key]) < 2:
            raise InputError(source, f"Table {key}", f"no Markdown table under a '## Table {key}' heading")
    return found


def _value(cell: str, source: str, number: int, column: str) -> dict:
    match = _CELL.match(cell)
    if not match:
        raise InputError(source, f"line {number}", f"column {column!r}: expected 'mean ± sd', got {cell!r}")
    return {"mean": float(match.group(1)), "sd": float(match.group(2))}


def _check_width(cells: list[str], width: int, source: str, number: int) -> None:
    if len(cells) != width:
        raise InputError(source, f"line {number}", f"{len(cells)} cells, the header has {width}")


def _table1(rows: list[tuple[int, list[str]]], source: str) -> dict:
    (_, header), body = rows[0], rows[1:]
    materials = header[1:]
    out: dict = {m: {} for m in materials}
    for number, cells in body:
        _check_width(cells, len(header), source, number)
        match = _ICOSPHERE.match(cells[0])
        if not match:
            raise InputError(source, f"line {number}", f"row label {cells[0]!r}: expected 'Icosphere N' "
                                                       "or 'Icosphere N*'")
        row = match.group(1) + match.group(2)
        for material, cell in zip(materials, cells[1:]):
            out[material][row] = _value(cell, source, number, material)
    return out


def _level(text: str, noise: str, source: str, number: int) -> str:
    match = _LEVEL.match(text)
    if not match:
        raise InputError(source, f"line {number}", f"σ {text!r}: expected a number and a unit (mm, °, %)")
    unit = _UNITS[match.group(2)]
    if unit != NOISE_TYPES[noise].unit:
        raise InputError(source, f"line {number}", f"σ {text!r}: {noise} is measured in "
                                                   f"{NOISE_TYPES[noise].unit}, not {unit}")
    return f"{float(match.group(1)):g}"


def _table2(rows: list[tuple[int, list[str]]], source: str) -> tuple[dict, dict]:
    (number, header), body = rows[0], rows[1:]
    if len(header) < 3 or header[1].lower() not in ("σ", "sigma"):
        raise InputError(source, f"line {number}", "Table 2's header must be '| noise | σ | material ... |'")
    materials = header[2:]
    table: dict = {}
    ideal: dict = {}
    noise: str | None = None
    for number, cells in body:
        _check_width(cells, len(header), source, number)
        label = cells[0].lower()
        if label == "ideal":
            ideal = {m: _value(c, source, number, m) for m, c in zip(materials, cells[2:])}
            noise = None
            continue
        if label:
            if label not in PAPER_NOISE_NAMES and label not in NOISE_TYPES:
                raise InputError(source, f"line {number}", f"unknown error type {cells[0]!r}; known: "
                                                           f"{', '.join(PAPER_NOISE_NAMES)}")
            noise = PAPER_NOISE_NAMES.get(label, label)
        elif noise is None:
            raise InputError(source, f"line {number}", "a row without an error type follows no error type's row")
        level = _level(cells[1], noise, source, number)
        table.setdefault(noise, {})[level] = {m: _value(c, source, number, m)
                                              for m, c in zip(materials, cells[2:])}
    return table, ideal


def parse_paper_tables(text: str, source: str = "<text>") -> PaperTables:
    """The paper's Tables 1 and 2 from Markdown ``text`` (see the module docstring).

    Parameters
    ----------
    text : str
        The Markdown.
    source : str
        Its file name, for error messages.

    Raises
    ------
    InputError
        A table is missing or malformed (the message names ``source`` and the line).
    """
    found = _tables_by_heading(text, source)
    table2, ideal = _table2(found["2"], source)
    return PaperTables(source=source, table1=_table1(found["1"], source), table2=table2, ideal=ideal)


def read_paper_tables(path: str | Path) -> PaperTables:
    """:func:`parse_paper_tables` of a file (UTF-8)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise InputError(path, "", f"cannot read the paper's tables: {error.strerror}") from None
    except UnicodeDecodeError:
        raise InputError(path, "", "not UTF-8 text") from None
    return parse_paper_tables(text, str(path))
