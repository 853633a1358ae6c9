"""Fitting: find the parameter values that make renderings match photographs (``abs.fit``),
their Laplace uncertainty, and the per-channel RMSE scans of the seed papers (``abs.scan``)."""

from abs.fitting.fit import FitResult, fit
from abs.fitting.optimisers import OptimizerState
from abs.fitting.scan import ScanResult, scan
from abs.fitting.settings import FitSettings

__all__ = ["fit", "FitResult", "FitSettings", "OptimizerState", "scan", "ScanResult"]
