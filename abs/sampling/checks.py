"""Plain-language checks of a sampling run: what its numbers imply that a user might not see.

A posterior is only as wide as its noise model allows. When the residual at the mode is larger
than the model's variance, every interval is too narrow by about the square root of the ratio;
when the chain stopped before emcee's rule was met, effective sample sizes and tail quantiles
are rough. Both are written into ``summary.json`` (``checks``), printed by ``abs sample`` and
shown at the top of the report.
"""

from __future__ import annotations

from collections.abc import Mapping

from abs.sampling.ensemble import TAU_FACTOR

__all__ = ["run_checks", "NOISE_MODEL_TOO_NARROW"]

#: Reduced chi^2 at the mode above which the noise model is said to understate the residual.
#: Calibrated runs measured 0.90-1.03 (docs/sampling.md, simulation-based calibration); the
#: README's capture, whose photographs carry heavy-tailed Monte-Carlo noise of their own, 1.71.
NOISE_MODEL_TOO_NARROW = 1.2


def run_checks(summary: Mapping) -> list[str]:
    """Warnings about a finished run, each a short message a user can act on.

    Parameters
    ----------
    summary : mapping
        The run's ``summary.json`` content (``noise.reduced_chi2_at_mode``, ``converged``,
        ``stop_reason``, ``steps``).

    Returns
    -------
    list of str
        Empty when nothing is wrong that these checks can see.
    """
    checks = []
    chi2 = (summary.get("noise") or {}).get("reduced_chi2_at_mode")
    if chi2 is not None and chi2 > NOISE_MODEL_TOO_NARROW:
        checks.append(
            f"The residual at the mode is {chi2:.2f} times the noise model's variance (about 1 "
            f"when the model is right): the intervals are probably too narrow by about "
            f"{chi2 ** 0.5:.2f}x. Likely causes: physics the scene leaves out (try abs diagnose) "
            "or photographs with noise the model does not know (e.g. rendered ones).")
    if not summary.get("converged", True):
        checks.append(
            f"The chain stopped ({summary.get('stop_reason')}) after {summary.get('steps')} steps, "
            f"before emcee's rule was met (a length of {TAU_FACTOR:g} autocorrelation times, with "
            "a stable estimate of them): effective sample sizes and the 5-95 % quantiles are "
            "rough; continue it with --resume and a larger budget.")
    return checks
