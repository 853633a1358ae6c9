"""The HTML report of a fit: metrics and parameter tables, convergence plots, per-view images.

Plotting and HTML only; the numbers come from the fit (``fit.json``'s summary, the iteration
history and the renderings before and after).
"""

from abs.report.fit_report import write_fit_report
from abs.report.view import ReportView

__all__ = ["write_fit_report", "ReportView"]
