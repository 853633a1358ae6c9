"""Errors raised for bad user input.

Every error that stems from a file a user wrote names the file and the field, so that the
message alone is enough to fix the input: ``scene.toml: materials.glass.ior: expected 3 numbers, got 2``.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["InputError", "SceneError", "CaptureError", "DeviceError"]


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
