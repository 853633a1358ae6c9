"""Fitting: find the parameter values that make renderings match photographs (``abs.fit``),
their Laplace uncertainty, and the per-channel RMSE scans of the seed papers (``abs.scan``).

The renderings and their derivatives come from the forward model (:mod:`abs.model`); a fit is
that model's weighted residuals (``objective.py``) handed to an optimiser registered by name
(``optimisers/``, one file each)."""

from abs.fitting.fit import FitResult, fit
from abs.fitting.optimisers import OptimizerState
from abs.fitting.scan import ScanResult, scan
from abs.fitting.settings import FitSettings

__all__ = ["fit", "FitResult", "FitSettings", "OptimizerState", "scan", "ScanResult"]
