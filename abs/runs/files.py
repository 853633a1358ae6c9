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


#: Relative tolerance of numbers in identities. Start values that a run computes from renders
#: (a diagnosis's trial starts at a score-test step) agree with its resume only to rounding:
#: measured, a stray-light start differed in the ninth digit, which restarted a finished fit.
IDENTITY_RTOL = 1e-6


def _same(a, b) -> bool:
    """Equal, with numbers compared to :data:`IDENTITY_RTOL` (booleans and strings exactly)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    numbers = (int, float)
    if (isinstance(a, numbers) and isinstance(b, numbers)
            and not isinstance(a, bool) and not isinstance(b, bool)):
        return abs(a - b) <= IDENTITY_RTOL * max(abs(a), abs(b))
    return a == b


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
        if not _same(saved.get(key), value):
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
