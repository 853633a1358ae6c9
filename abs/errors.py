"""Errors raised for bad user input, and the one reader of a user's JSON file.

Every error that stems from a file a user wrote names the file and the field, so that the
message alone is enough to fix the input: ``scene.toml: materials.glass.ior: expected 3 numbers, got 2``.

Every reader of a JSON input in abs (camera files, capture folders, build files, colour
corrections, volume headers, checkpoints, ...) starts the same way: read the text, decode it, check
that the top level is the expected kind of value. :func:`read_json` does those three steps once, so
a missing file, a file that is not UTF-8 text, malformed JSON and a wrong top-level type give the
same kind of :class:`InputError` everywhere: ``cameras.json: not valid JSON: Expecting ','
delimiter at line 3, column 5``. What the values mean stays with each reader. It lives here, in
layer 0 of docs/architecture.md, because those readers live in every layer, ``colour`` below
``io`` included.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["InputError", "SceneError", "CaptureError", "DeviceError", "read_json"]


class InputError(ValueError):
    """A user-supplied file or value is malformed.

    Parameters
    ----------
    source : str or Path or None
        The file the bad value came from (``None`` for values passed from Python).
    field : str
        Dotted path of the offending field inside that file, e.g. ``materials.glass.ior``.
    message : str
        What is wrong and, where possible, what was expected.
    """

    def __init__(self, source: str | Path | None, field: str, message: str):
        self.source = None if source is None else str(source)
        self.field = field
        self.message = message
        where = f"{self.source}: " if self.source else ""
        super().__init__(f"{where}{field}: {message}" if field else f"{where}{message}")


class SceneError(InputError):
    """A scene file (TOML) or one of its assets is malformed."""


class CaptureError(InputError):
    """A capture folder (``cameras.json`` and its images) is malformed."""


class DeviceError(RuntimeError):
    """An acquisition device stopped answering or answered nonsense."""


# The JSON name of each Python type ``json`` decodes to, for "expected an object, got an array".
_JSON_NAMES = {dict: "object", list: "array", str: "string", int: "number", float: "number",
               bool: "true/false", type(None): "null"}


def _as_tuple(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)


def _json_name(kind: type | tuple[type, ...]) -> str:
    """``"object"``, ``"object or array"``: the JSON name(s) of Python type(s)."""
    return " or ".join(dict.fromkeys(_JSON_NAMES.get(k, k.__name__) for k in _as_tuple(kind)))


def read_json(path: str | Path, *, what: str = "file", field: str = "",
              expect: type | tuple[type, ...] | None = dict, hint: str = "",
              error: type[InputError] = InputError) -> Any:
    """Decode a JSON file, turning every way it can be unreadable into one error type.

    Parameters
    ----------
    path : str or Path
        The JSON file.
    what : str
        What the file is, for the messages (``"camera file"`` gives ``camera file not found``).
    field : str
        The field the errors name; ``""`` (the default) for the file as a whole. A caller whose
        file came from an option may name the option (``"--study"``).
    expect : type or tuple of type or None
        The Python type(s) the top-level value must decode to (``dict`` for a JSON object, the
        default; ``(dict, list)`` for either); ``None`` accepts any value.
    hint : str
        Appended to every message, e.g. what to do (``"delete it to start over"``).
    error : type of InputError
        The error raised: :class:`~abs.errors.InputError` or a subclass (``CaptureError``).

    Returns
    -------
    Any
        The decoded value.

    Raises
    ------
    InputError
        (or ``error``) if the file is missing, is a folder, cannot be read or decoded as UTF-8,
        is not valid JSON (position given as line and column), or its top level is not ``expect``.
    """
    path = Path(path)
    tail = f" ({hint})" if hint else ""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(path, field, f"{what} not found{tail}") from None
    except IsADirectoryError:
        raise error(path, field, f"expected a {what}, got a folder{tail}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(path, field, f"cannot read the {what}: {exc}{tail}") from exc
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(path, field, f"not valid JSON: {exc.msg} at line {exc.lineno}, column "
                                 f"{exc.colno}{tail}") from exc
    # bool is an int in Python but not a number in a JSON file: ``true`` is not a count.
    if expect is not None and (not isinstance(data, expect)
                               or (isinstance(data, bool) and bool not in _as_tuple(expect))):
        raise error(path, field, f"expected a JSON {_json_name(expect)} at the top of the "
                                 f"{what}, got {_json_name(type(data))}{tail}")
    return data
