"""Typed readers for fields of a scene file, each raising a :class:`SceneError` that names the
file and the dotted field path. Material plugins use these, so every plugin reports bad input the
same way."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from abs.errors import SceneError

__all__ = ["Fields"]

_MISSING = object()


def _has_bool(value: Any) -> bool:
    """TOML ``true`` anywhere in a (nested) list; numpy would silently read it as 1."""
    return isinstance(value, bool) or (isinstance(value, list) and any(map(_has_bool, value)))


@dataclass(frozen=True)
class Fields:
    """A TOML table together with where it came from.

    Parameters
    ----------
    table : dict
        The parsed TOML table.
    source : Path
        The scene file, for error messages and for resolving relative asset paths.
    prefix : str
        Dotted path of this table inside the file, e.g. ``materials.glass``.
    files : dict
        Asset paths resolved by :meth:`file`, keyed by dotted field path; shared with the tables
        :meth:`sub` returns, so that a scene can be written elsewhere with its asset paths
        rewritten (:func:`abs.scene.write.write_scene`) without each material declaring them.
    """

    table: dict
    source: Path
    prefix: str
    files: dict[str, Path] = field(default_factory=dict, compare=False, repr=False)

    def path(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, message: str) -> SceneError:
        return SceneError(self.source, self.path(key), message)

    def sub(self, key: str, required: bool = True) -> "Fields | None":
        value = self.table.get(key, _MISSING)
        if value is _MISSING:
            if required:
                raise self.error(key, "missing table")
            return None
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {type(value).__name__}")
        return Fields(value, self.source, self.path(key), self.files)

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        if key not in self.table:
            if default is _MISSING:
                raise self.error(key, "missing field")
            return default
        return self.table[key]

    def check_known(self, known: set[str]) -> None:
        """Reject misspelt keys: a silently ignored ``absorbtion`` would fit the wrong thing."""
        for key in self.table:
            if key not in known:
                raise self.error(key, f"unknown field; expected one of {sorted(known)}")

    def string(self, key: str, default: Any = _MISSING) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str) or not value:
            raise self.error(key, f"expected a non-empty string, got {value!r}")
        return value

    def number(self, key: str, default: Any = _MISSING, lower: float | None = None,
               upper: float | None = None, integer: bool = False) -> float:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f"expected a number, got {value!r}")
        if integer and not float(value).is_integer():
            raise self.error(key, f"expected an integer, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, f"expected a finite number, got {value!r}")
        if lower is not None and value < lower:
            raise self.error(key, f"must be >= {lower}, got {value}")
        if upper is not None and value > upper:
            raise self.error(key, f"must be <= {upper}, got {value}")
        return int(value) if integer else value

    def array(self, key: str, shape: tuple[int, ...], default: Any = _MISSING,
              lower: float | None = None, upper: float | None = None) -> np.ndarray:
        return self._array(key, self.raw(key, default), shape, lower, upper)

    def _array(self, key: str, value: Any, shape: tuple[int, ...], lower: float | None,
               upper: float | None) -> np.ndarray:
        try:
            arr = np.asarray(value)
        except (TypeError, ValueError):  # ragged nesting
            arr = None
        # Checked before converting: numpy would turn "1.5" and true into numbers.
        if arr is None or arr.dtype.kind not in "iuf" or _has_bool(value):
            raise self.error(key, f"expected numbers of shape {list(shape)}, got {value!r}")
        arr = arr.astype(np.float64)
        if arr.shape != shape:
            raise self.error(key, f"expected shape {list(shape)}, got {list(arr.shape)}")
        if not np.all(np.isfinite(arr)):
            raise self.error(key, f"contains NaN or infinity: {value!r}")
        if lower is not None and np.any(arr < lower):
            raise self.error(key, f"all entries must be >= {lower}, got {arr.tolist()}")
        if upper is not None and np.any(arr > upper):
            raise self.error(key, f"all entries must be <= {upper}, got {arr.tolist()}")
        return arr

    def vector(self, key: str, size: int, default: Any = _MISSING, lower: float | None = None,
               upper: float | None = None) -> np.ndarray:
        """``size`` numbers; a single number means the same for all of them."""
        value = self.raw(key, default)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = [value] * size
        return self._array(key, value, (size,), lower, upper)

    def rgb(self, key: str, default: Any = _MISSING, lower: float | None = None,
            upper: float | None = None) -> np.ndarray:
        """A per-channel (R, G, B) quantity; a single number means the same in all channels."""
        return self.vector(key, 3, default, lower, upper)

    def file(self, key: str, default: Any = _MISSING, suffixes: tuple[str, ...] = ()) -> Path:
        """A path relative to the scene file that must exist."""
        name = self.string(key, default)
        path = (self.source.parent / name).resolve()
        if suffixes and path.suffix.lower() not in suffixes:
            raise self.error(key, f"unsupported file type {path.suffix!r}; expected {', '.join(suffixes)}")
        if not path.is_file():
            raise self.error(key, f"file not found: {path}")
        self.files[self.path(key)] = path
        return path

    def files_below(self) -> dict[str, Path]:
        """Files resolved by :meth:`file` in this table and its sub-tables, keyed by field path
        relative to this table (``reflectance``, not ``materials.cloth.reflectance``)."""
        if not self.prefix:
            return dict(self.files)
        start = self.prefix + "."
        return {key[len(start):]: path for key, path in self.files.items() if key.startswith(start)}

    def transform(self, key: str) -> np.ndarray:
        """An optional row-major 4x4 affine matrix (identity when absent)."""
        if key not in self.table:
            return np.eye(4)
        m = self.array(key, (4, 4))
        if not np.allclose(m[3], [0, 0, 0, 1]):
            raise self.error(key, f"last row must be [0, 0, 0, 1], got {m[3].tolist()}")
        if abs(np.linalg.det(m[:3, :3])) < 1e-12:
            raise self.error(key, "the 3x3 part is singular")
        return m
