"""Spectral optical constants from refractiveindex.info YAML files.

The refractiveindex.info database stores a material's complex refractive index ``n + i k`` as a
list of ``DATA`` blocks: tabulated ``n k`` / ``n`` / ``k`` columns against the wavelength in
micrometres, or a dispersion formula for ``n`` with its coefficients and validity range. This
module reads one such file (``yaml.safe_load`` only: the file is data) into
:class:`OpticalConstants`, which evaluates ``n`` and ``k`` at any wavelength in its range.

Formulas implemented (refractiveindex.info numbering; ``λ`` in µm, ``C1, C2, ...`` the
coefficients):

- ``formula 1`` (Sellmeier): ``n² - 1 = C1 + Σ C(i) λ² / (λ² - C(i+1)²)``
- ``formula 2`` (Sellmeier-2, SCHOTT catalogue): ``n² - 1 = C1 + Σ C(i) λ² / (λ² - C(i+1))``
- ``formula 3`` (polynomial): ``n² = C1 + Σ C(i) λ^C(i+1)``
- ``formula 5`` (Cauchy): ``n = C1 + Σ C(i) λ^C(i+1)``

Tabulated values are interpolated linearly in wavelength; nothing is extrapolated (a wavelength
outside a block's range is an error naming the file and block).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from abs.errors import InputError

__all__ = ["OpticalConstants", "read_refractiveindex_yaml", "FORMULAS"]

_UM = 1e-6  # metres per micrometre


def _sellmeier(c: np.ndarray, lam: np.ndarray) -> np.ndarray:
    l2 = lam**2
    n2 = 1.0 + c[0] + sum(c[i] * l2 / (l2 - c[i + 1] ** 2) for i in range(1, len(c) - 1, 2))
    return np.sqrt(n2)


def _sellmeier2(c: np.ndarray, lam: np.ndarray) -> np.ndarray:
    l2 = lam**2
    n2 = 1.0 + c[0] + sum(c[i] * l2 / (l2 - c[i + 1]) for i in range(1, len(c) - 1, 2))
    return np.sqrt(n2)


def _polynomial(c: np.ndarray, lam: np.ndarray) -> np.ndarray:
    n2 = c[0] + sum(c[i] * lam ** c[i + 1] for i in range(1, len(c) - 1, 2))
    return np.sqrt(n2)


def _cauchy(c: np.ndarray, lam: np.ndarray) -> np.ndarray:
    return c[0] + sum(c[i] * lam ** c[i + 1] for i in range(1, len(c) - 1, 2))


#: Dispersion formulas by their refractiveindex.info ``type``; each maps (coefficients, λ in µm)
#: to n. Adding a formula is adding an entry.
FORMULAS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "formula 1": _sellmeier,
    "formula 2": _sellmeier2,
    "formula 3": _polynomial,
    "formula 5": _cauchy,
}


@dataclass(frozen=True)
class _Block:
    """One quantity (``n`` or ``k``) over a wavelength range [m], from one DATA block."""

    range_m: tuple[float, float]
    evaluate: Callable[[np.ndarray], np.ndarray]  # wavelength [m] -> value
    kind: str  # the block's ``type`` (for messages)
    index: int  # its position in DATA (for messages)


@dataclass(frozen=True)
class OpticalConstants:
    """Complex refractive index ``n + i k`` of one material as functions of wavelength.

    Attributes
    ----------
    source : str
        The file it was read from (named in errors and written beside derived values).
    references : str
        The file's ``REFERENCES`` text (who measured or published the data).
    """

    source: str
    references: str
    _n: _Block | None = field(repr=False, default=None)
    _k: _Block | None = field(repr=False, default=None)

    @property
    def has_k(self) -> bool:
        """Whether the file gives the extinction coefficient ``k``."""
        return self._k is not None

    def range_m(self, quantity: str) -> tuple[float, float]:
        """Wavelength range [m] over which ``quantity`` (``"n"`` or ``"k"``) is defined."""
        return self._block(quantity).range_m

    def n(self, wavelength_m: np.ndarray) -> np.ndarray:
        """Real refractive index at ``wavelength_m`` (metres, vacuum wavelength)."""
        return self._eval("n", wavelength_m)

    def k(self, wavelength_m: np.ndarray) -> np.ndarray:
        """Extinction coefficient (imaginary part of the index, dimensionless) at ``wavelength_m``."""
        return self._eval("k", wavelength_m)

    def _block(self, quantity: str) -> _Block:
        block = self._n if quantity == "n" else self._k
        if block is None:
            raise InputError(self.source, "DATA", f"no {quantity} in this file (no 'tabulated "
                             f"{quantity}', 'tabulated nk'{' or formula' if quantity == 'n' else ''}"
                             " block)")
        return block

    def _eval(self, quantity: str, wavelength_m) -> np.ndarray:
        block = self._block(quantity)
        lam = np.asarray(wavelength_m, dtype=np.float64)
        lo, hi = block.range_m
        # A relative tolerance keeps tabulated end points usable after unit conversion.
        if np.any(lam < lo * (1 - 1e-9)) or np.any(lam > hi * (1 + 1e-9)):
            raise InputError(self.source, f"DATA[{block.index}]",
                             f"{block.kind!r} covers {lo * 1e9:.1f}-{hi * 1e9:.1f} nm, but "
                             f"{quantity} was asked for at {lam.min() * 1e9:.1f}-"
                             f"{lam.max() * 1e9:.1f} nm (no extrapolation)")
        return block.evaluate(np.clip(lam, lo, hi))


def _numbers(source: str, where: str, text, columns: int | None) -> np.ndarray:
    try:
        values = np.array([[float(x) for x in line.split()] for line in str(text).strip().splitlines()
                           if line.strip()], dtype=np.float64)
    except ValueError as exc:
        raise InputError(source, where, f"not a table of numbers ({exc})") from exc
    if values.ndim != 2 or values.size == 0 or (columns and values.shape[1] != columns):
        raise InputError(source, where, f"expected rows of {columns} numbers")
    if np.any(np.diff(values[:, 0]) <= 0):
        raise InputError(source, where, "wavelengths must increase strictly")
    return values


def _table(values: np.ndarray, column: int) -> Callable[[np.ndarray], np.ndarray]:
    lam_m, y = values[:, 0] * _UM, values[:, column]
    return lambda wavelength_m: np.interp(wavelength_m, lam_m, y)


def read_refractiveindex_yaml(path: str | Path) -> OpticalConstants:
    """Read a refractiveindex.info material file.

    Parameters
    ----------
    path : str or Path
        A ``.yml`` file in the refractiveindex.info database layout (``DATA`` list).

    Returns
    -------
    OpticalConstants
        ``n`` from the first block that gives it (formula, ``tabulated n`` or ``tabulated nk``),
        ``k`` from the first that gives it (``tabulated k`` or ``tabulated nk``), if any.

    Raises
    ------
    InputError
        Naming the file and field: missing file, not YAML, no ``DATA``, an unknown block type,
        malformed numbers.
    """
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise InputError(source, "", "no such file")
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(source, "", f"not a YAML file: {exc}") from exc
    if not isinstance(doc, dict) or not isinstance(doc.get("DATA"), list) or not doc["DATA"]:
        raise InputError(source, "DATA", "missing or empty: expected a list of data blocks")
    n_block = k_block = None
    for i, block in enumerate(doc["DATA"]):
        where = f"DATA[{i}]"
        kind = block.get("type") if isinstance(block, dict) else None
        if not isinstance(kind, str):
            raise InputError(source, f"{where}.type", "missing")
        if kind in FORMULAS:
            try:
                coeffs = np.array([float(x) for x in str(block.get("coefficients", "")).split()])
            except ValueError as exc:
                raise InputError(source, f"{where}.coefficients", f"not numbers ({exc})") from exc
            if coeffs.size < 1:
                raise InputError(source, f"{where}.coefficients", "missing")
            try:
                lo, hi = (float(x) * _UM for x in str(block["wavelength_range"]).split())
            except (KeyError, ValueError) as exc:
                raise InputError(source, f"{where}.wavelength_range", "expected two numbers (µm)") from exc
            formula = FORMULAS[kind]
            blk = _Block((lo, hi), lambda lam, c=coeffs, f=formula: f(c, lam / _UM), kind, i)
            n_block = n_block or blk
        elif kind in ("tabulated nk", "tabulated n", "tabulated k"):
            columns = 3 if kind == "tabulated nk" else 2
            values = _numbers(source, f"{where}.data", block.get("data", ""), columns)
            rng = (values[0, 0] * _UM, values[-1, 0] * _UM)
            if kind != "tabulated k":
                n_block = n_block or _Block(rng, _table(values, 1), kind, i)
            if kind != "tabulated n":
                k_block = k_block or _Block(rng, _table(values, columns - 1), kind, i)
        else:
            raise InputError(source, f"{where}.type", f"unsupported {kind!r}; supported: "
                             f"{', '.join(FORMULAS)}, tabulated nk, tabulated n, tabulated k")
    return OpticalConstants(source, str(doc.get("REFERENCES", "")).strip(), n_block, k_block)
