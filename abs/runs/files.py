"""Files every run folder shares: JSON written atomically, and optimiser checkpoints.

Checkpoints are JSON (never pickles): the optimiser state plus the identity of the run it belongs
to (:mod:`abs.runs.identity`), so a resume with a different scene, capture, parameter list or
settings is refused instead of silently mixed. Files are written to a temporary name and renamed,
so an interruption never leaves half a file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from abs.errors import InputError, read_json

__all__ = ["write_json", "save_checkpoint", "load_checkpoint", "check_identity", "CHECKPOINT_FILE"]

CHECKPOINT_FILE = "checkpoint.json"


def write_json(path: str | Path, data) -> Path:
    """Write ``data`` as indented JSON atomically (temporary file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, allow_nan=False))
    os.replace(tmp, path)
    return path


def check_identity(path: Path, field: str, saved: dict, identity: dict, made: str, hint: str) -> None:
    """Refuse a saved run whose identity differs from this run's, naming the first differing key.

    Parameters
    ----------
    path : Path
        The saved file (checkpoint, chain), named in the error.
    field : str
        Prefix of the differing key in the error (``fit``, ``abs``).
    saved, identity : dict
        The saved identity and this run's.
    made : str
        What the saved file was made by, for the message ("checkpoint was made",
        "chain was sampled").
    hint : str
        How to get going again.

    Raises
    ------
    InputError
        On the first key of ``identity`` whose saved value differs.
    """
    for key, value in identity.items():
        if saved.get(key) != value:
            raise InputError(path, f"{field}.{key}", f"{made} with {saved.get(key)!r}, this run has "
                             f"{value!r}; {hint}")


def save_checkpoint(folder: str | Path, identity: dict, state: dict) -> Path:
    """Save an optimiser state (``OptimizerState.to_dict()``) with the identity of its fit."""
    return write_json(Path(folder) / CHECKPOINT_FILE, {"version": 1, "fit": identity, "state": state})


def load_checkpoint(folder: str | Path, identity: dict) -> dict | None:
    """The saved optimiser state of the same fit, or ``None`` when there is no checkpoint.

    Raises
    ------
    InputError
        If the checkpoint is unreadable or belongs to a different fit (naming the differing field).
    """
    path = Path(folder) / CHECKPOINT_FILE
    if not path.exists():
        return None
    data = read_json(path, what="abs checkpoint", hint="delete it to start over")
    try:
        saved, state = data["fit"], data["state"]
    except KeyError as exc:
        raise InputError(path, str(exc.args[0]), "missing: not an abs checkpoint; delete it to "
                                                 "start over") from None
    check_identity(path, "fit", saved, identity, "checkpoint was made",
                   "use another --out folder or delete the checkpoint")
    return state
