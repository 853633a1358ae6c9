"""Files of a fit: ``fit.json`` (public contract), checkpoints, fitted renderings.

A fit folder holds::

    fit.json          the summary (docs/fit-output.md)
    scene.toml        the fitted scene file (same format, fitted parameters replaced)
    checkpoint.json   the optimiser state after the last completed iteration (for --resume)
    renders/          EXR renderings of every view with the fitted parameters
    report/           report.html and its PNGs

Checkpoints are JSON (never pickles): the optimiser state plus what it belongs to, so a resume
with a different scene, capture, parameter list or settings is refused instead of silently mixed.
Files are written to a temporary name and renamed, so an interruption never leaves half a file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from abs.errors import InputError

__all__ = ["write_json", "save_checkpoint", "load_checkpoint", "write_fit_folder", "CHECKPOINT_FILE",
           "FIT_FILE"]

CHECKPOINT_FILE = "checkpoint.json"
FIT_FILE = "fit.json"


def write_json(path: str | Path, data) -> Path:
    """Write ``data`` as indented JSON atomically (temporary file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2, allow_nan=False))
    os.replace(tmp, path)
    return path


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
    try:
        data = json.loads(path.read_text())
        saved, state = data["fit"], data["state"]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise InputError(path, "", f"not a valid abs checkpoint ({exc}); delete it to start over") from None
    for key, value in identity.items():
        if saved.get(key) != value:
            raise InputError(path, f"fit.{key}", f"checkpoint was made with {saved.get(key)!r}, this "
                             f"run has {value!r}; use another --out folder or delete the checkpoint")
    return state


def write_fit_folder(folder: str | Path, scene, result, report: bool = True) -> dict:
    """Write a fit's outputs: ``fit.json``, the fitted ``scene.toml``, ``renders/*.exr`` and
    (unless ``report=False``) ``report/report.html``. Returns the summary (``fit.json``)."""
    from abs.io.images import write_exr
    from abs.report import ReportView, write_fit_report
    from abs.scene.write import write_scene

    folder = Path(folder)
    summary = result.summary()
    write_json(folder / FIT_FILE, summary)
    write_scene(scene, folder / "scene.toml", result.values)
    (folder / "renders").mkdir(parents=True, exist_ok=True)
    for view in result.views:
        write_exr(folder / "renders" / f"{view.name}.exr", view.after.astype("float32"))
    if report:
        views = [ReportView(v.name, v.holdout, v.photograph, v.before, v.after) for v in result.views]
        write_fit_report(folder / "report", summary, views, result.history)
    return summary
