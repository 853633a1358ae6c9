"""Where abs finds the shared measured data (not in the repository) and keeps derived caches.

The shared data folder holds real measured data that is not committed to the repository
(``../shared/data`` beside the repository root, as in CI; see ``../shared/README.md``). Derived
files that are slow to rebuild (MERL tables evaluated from the neural fits, ...) are cached on
disk, never committed.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["shared_data_dir", "cache_dir"]

_REPO_ROOT = Path(__file__).resolve().parents[2]


def shared_data_dir() -> Path:
    """The shared data folder: ``$ABS_SHARED_DATA`` when set, else ``../shared/data`` next to the
    repository root. The folder may not exist; callers check and explain."""
    env = os.environ.get("ABS_SHARED_DATA")
    return Path(env) if env else _REPO_ROOT.parent / "shared" / "data"


def cache_dir(kind: str) -> Path:
    """A cache folder for derived data of one ``kind`` (e.g. ``"merl"``), created if needed:
    ``$ABS_CACHE/<kind>`` when ``ABS_CACHE`` is set, else ``~/.cache/abs/<kind>``."""
    root = Path(os.environ["ABS_CACHE"]) if os.environ.get("ABS_CACHE") else Path.home() / ".cache" / "abs"
    path = root / kind
    path.mkdir(parents=True, exist_ok=True)
    return path
