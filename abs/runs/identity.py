"""What makes two runs the same run: the identities that resumes and caches compare.

A resumed run must continue the run it claims to continue: a checkpoint, chain file or cached
result is only reused when the identity saved with it equals this run's, and refused (or
recomputed) otherwise. The recipes differ on purpose, and each is kept exactly as it was, because
the identities are saved in existing run folders and a changed recipe would refuse them:

- :func:`run_identity`: a fit or a sampling run, by scene file path, capture folder, parameter
  names, start values and the settings the result depends on (``abs fit``, ``abs sample``);
- :func:`model_identity`: a fit of a scene file that a diagnosis writes and rewrites, so the
  file is identified by its contents (a digest) rather than its path (``abs diagnose``);
- :func:`digest`: a short hash of any identity, for caches keyed by it (saved short fits of a
  diagnosis, the tasks of a study).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

__all__ = ["run_identity", "model_identity", "digest"]


def _capture_folder(capture) -> str:
    folder = capture.folder if hasattr(capture, "folder") else Path(capture)
    return str(Path(folder).resolve())


def _capture_entries(capture) -> dict:
    """The capture's entries of an identity: its folder, and ``pixel_weights`` only when its
    photographs come with noise images (residuals are then weighed, docs/fitting.md): a capture
    rebuilt in place with them is another run, and runs saved before noise images existed keep
    their identity."""
    from abs.errors import CaptureError
    from abs.io.capture import load_capture

    entries = {"capture": _capture_folder(capture)}
    try:
        loaded = capture if hasattr(capture, "views") else load_capture(capture)
    except CaptureError:  # not a capture (yet): the run itself says so, naming the file
        return entries
    if any(v.noise is not None for v in loaded.views):
        entries["pixel_weights"] = True
    return entries


_ADDED_LATER = ("tie",)


def _settings(settings, keep: Iterable[str] | None, drop: Iterable[str]) -> dict:
    # Through JSON, so tuples compare equal to the lists a saved identity reads back as.
    values = json.loads(json.dumps(asdict(settings)))
    # Settings added after runs were saved enter only when set, so those runs still resume.
    for name in _ADDED_LATER:
        if name in values and not values[name]:
            del values[name]
    if keep is not None:
        values = {k: values[k] for k in keep if k in values}
    return {k: v for k, v in values.items() if k not in set(drop)}


def run_identity(scene, capture, names: Sequence[str], settings, *, initial: Mapping | None = None,
                 keep: Iterable[str] | None = None, drop: Iterable[str] = ()) -> dict:
    """The identity of a fit or sampling run.

    Parameters
    ----------
    scene : Scene or path
        The scene (its ``source`` file path is used).
    capture : path or Capture
        The capture folder.
    names : sequence of str
        Parameter names.
    settings : dataclass
        The run's settings; only ``keep`` (all when ``None``) minus ``drop`` enter the identity.
        Settings that only extend a run (more iterations, a longer chain) belong in ``drop``, so
        that extending a run is a resume rather than a different run.
    initial : mapping, optional
        Start values; entered (as given) only when not ``None``.
    """
    identity = {"scene": str(getattr(scene, "source", scene)), **_capture_entries(capture),
                "parameters": list(names)}
    if initial is not None:
        identity["initial"] = initial
    identity["settings"] = _settings(settings, keep, drop)
    return identity


def model_identity(scene, capture, names: Sequence[str], initial: Mapping[str, object], settings) -> dict:
    """The identity of a fit of a model file that a diagnosis wrote (checkpoints, saved short
    fits): the scene file's digest, the capture folder, the parameters, their start and all the
    settings."""
    text = Path(scene.source).read_bytes()
    return {"scene": hashlib.sha256(text).hexdigest(), **_capture_entries(capture),
            "parameters": list(names), "initial": {n: np.asarray(v).tolist() for n, v in initial.items()},
            "settings": _settings(settings, None, ())}


def digest(identity, length: int = 16) -> str:
    """A hex digest (``length`` characters) of a JSON-serialisable identity, key order ignored."""
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:length]
