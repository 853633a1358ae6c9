"""Registered effects: every module of this package is imported, so adding one is adding a file."""

import importlib
import pkgutil

from abs.diagnosis.effects.base import Candidate, Effect, effect, effects, register

for _info in pkgutil.iter_modules(__path__):
    if _info.name != "base":
        importlib.import_module(f"{__name__}.{_info.name}")

__all__ = ["Candidate", "Effect", "effect", "effects", "register"]
