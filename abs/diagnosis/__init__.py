"""Find the missing physics: locate where a fitted scene disagrees with the photographs, rank the
catalogue of effects the scene file leaves out, fit the strongest, and accept one only if it
improves the holdout views and a penalised criterion prefers it (``abs diagnose``)."""

from abs.diagnosis.diagnose import DEFAULT_SETTINGS, Diagnosis, diagnose

__all__ = ["diagnose", "Diagnosis", "DEFAULT_SETTINGS"]
