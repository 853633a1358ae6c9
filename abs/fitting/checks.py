"""Plain-language checks of a finished fit: the signs that it failed, said where a user looks.

A least-squares fit always returns numbers. These checks read the fit's own summary for the signs
that those numbers are not a solution: a direction the photographs do not constrain (the Laplace
curvature is singular there) or constrain so loosely that the value is not measured, a parameter
pinned at a bound or outside the range its material can physically have (a glass IOR of 2.18 is
no glass; a fit there found a wrong basin), a parameter that the renders' Monte-Carlo noise rather
than the photographs moved (its refinement steps cut to the trust radius nearly every time),
standard errors without the renders' Monte-Carlo part (too few refinement steps to measure it), two
parameters that trade off almost perfectly, and a holdout residual that stays far above the
photographs' noise (the model leaves out physics, or the fit stopped in a wrong minimum), and a
last polish along the objective that did not reach its minimum. They are written to ``fit.json``
(``checks``), printed by ``abs fit`` and shown at the top of the report, as
:mod:`abs.sampling.checks` does for posteriors.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["run_checks", "at_bound", "PLAUSIBLE_RANGES", "HOLDOUT_NOISE_FACTOR",
           "TRADE_OFF_CORRELATION", "NOISE_WALK_SHARE"]

#: Physically plausible values by ``(material type, field)``: what real materials of that type
#: have. A fit outside them has almost surely found a wrong basin. Glass IORs: optical and
#: soda-lime glasses in the visible (refractiveindex.info: fused silica 1.46 to dense flints
#: 1.8); absorption of clear to strongly tinted glass, 1/m.
PLAUSIBLE_RANGES: dict[tuple[str, str], tuple[float, float]] = {
    ("dielectric", "ior"): (1.45, 1.8),
    ("dielectric", "absorption"): (0.0, 200.0),
}

#: Holdout RMSE above this many times the photographs' own noise: the model does not explain the
#: views it was not fitted to.
HOLDOUT_NOISE_FACTOR = 3.0

#: |correlation| above which two parameters are said to trade off.
TRADE_OFF_CORRELATION = 0.98

#: Share of the refinement's steps (after its first quarter) cut to the trust radius at or above
#: which a component was moved by the renders' noise. A Newton step that scatters normally with
#: standard deviation ``s`` typical steps exceeds a radius of one that often only for ``s`` of 2.3
#: or more. Glass suite (120x100 compared at 60x50, 64 spp, 16 steps; counted on the benchmark's
#: traces): the spheres' IORs 1-3 of 11 steps, their absorptions clear of the bound 2-6 of 11; the
#: bowl's IOR 10 of 11 (1.733 +- 0.014 for 1.52) and 9 of 12 in a rerun (1.071 +- 0.024). The
#: spheres rerun with the record: IORs 1-3 of 12, absorptions clear of the bound 2-4 of 12.
NOISE_WALK_SHARE = 2.0 / 3.0

# How many standard errors from a finite bound a value must be for the noise-walk check: a walk
# at the bound (clear glass at absorption 0) is the bound check's, and there only the
# unconstrained coordinate wanders, not the value.
_WALK_CLEAR_OF_BOUND = 2.0

# A value this close to a bound (relative to the bound's scale) counts as "at" it.
_AT_BOUND = 1e-3


def at_bound(value: float, lower: float, upper: float) -> str | None:
    """Which bound ``value`` sits at (``"lower bound 0"``), or ``None``: within ``_AT_BOUND`` of
    it, relative to the bound's size (at least 1)."""
    for bound, word in ((lower, "lower"), (upper, "upper")):
        if np.isfinite(bound) and abs(value - bound) <= _AT_BOUND * max(1.0, abs(bound)):
            return f"{word} bound {bound:g}"
    return None


def _noise_walk(name: str, entry: Mapping, values: np.ndarray, stderr: Sequence,
                lower: float, upper: float) -> list[str]:
    """The check of a parameter whose refinement steps were cut to the trust radius nearly every
    time (``refinement_limited`` in its ``fit.json`` entry): its curvature from two noisy
    Jacobians is Monte-Carlo noise, so each Gauss-Newton step is arbitrarily long and the
    refinement walks at random; the mean of the walk is not the solution and the walk's scatter
    understates the error. One message for a tied parameter (equal components)."""
    shares = entry.get("refinement_limited")
    if not shares:
        return []
    flagged = []
    for i, (v, share) in enumerate(zip(values, shares)):
        s = stderr[i] if i < len(stderr) else None
        if share is None or share < NOISE_WALK_SHARE or s is None:
            continue
        if any(np.isfinite(b) and abs(v - b) <= _WALK_CLEAR_OF_BOUND * s for b in (lower, upper)):
            continue
        flagged.append(i)
    if not flagged:
        return []
    tied = (len(values) > 1 and len(flagged) == len(values) and np.ptp(values) == 0
            and np.ptp(shares) == 0)
    labels = [(name, 0)] if tied else [(f"{name}[{i}]", i) for i in flagged]
    return [f"{label} = {values[i]:.4g} +- {stderr[i]:.2g}: in {shares[i]:.0%} of the refinement's "
            "steps the Gauss-Newton step was longer than its trust radius, so the renders' "
            "Monte-Carlo noise, not the photographs, moved it (its curvature is noise at these "
            "samples). The value is the end of a random walk, not a measurement, and its standard "
            "error is too small. Raise --spp (the renders' noise dominates), add views that show "
            "it, or give a prior." for label, i in labels]


def run_checks(summary: Mapping, bounds: Mapping[str, tuple[float, float]],
               kinds: Mapping[str, tuple[str, str]] | None = None,
               steps: Mapping[str, Sequence[float]] | None = None) -> list[str]:
    """Warnings about a finished fit, each a short message a user can act on.

    Parameters
    ----------
    summary : mapping
        The fit's ``fit.json`` content (``parameters`` with ``value``, ``stderr`` and, after a
        Gauss-Newton refinement, ``refinement_limited``; ``correlation``, ``holdout_rmse``,
        ``train_rmse``, ``image_noise``).
    bounds : mapping
        Parameter name to its physical ``(lower, upper)`` bounds.
    kinds : mapping, optional
        Parameter name to ``(material type, field)`` for the plausibility ranges.
    steps : mapping, optional
        Parameter name to the typical change of each component (its units): an error larger
        than both this and half the value (from a finite lower bound) says the value is not
        measured.

    Returns
    -------
    list of str
        Empty when nothing is wrong that these checks can see.
    """
    checks = []
    kinds = kinds or {}
    for name, entry in summary["parameters"].items():
        values = np.atleast_1d(np.asarray(entry["value"], float))
        stderr = entry.get("stderr") or [None] * len(values)
        loose = [i for i, s in enumerate(stderr) if s is None]
        if loose:
            which = "every component" if len(loose) == len(values) else f"component(s) {loose}"
            checks.append(
                f"{name}: the photographs do not constrain {which} (the curvature of the fit is "
                "singular there), so no standard error can be given and the value is not "
                "determined by the data. Fit fewer parameters (tie per-channel values), add views "
                "that show the effect, or give a prior.")
        lower, upper = bounds.get(name, (-np.inf, np.inf))
        if steps is not None and name in steps:
            step = np.broadcast_to(np.asarray(steps[name], float), values.shape)
            origin = lower if np.isfinite(lower) else 0.0
            for i, (v, s) in enumerate(zip(values, stderr)):
                if s is not None and s > max(0.5 * abs(v - origin), step[i]):
                    checks.append(
                        f"{name}[{i}] = {v:.4g} +- {s:.2g}: the photographs determine it only to "
                        f"more than half its value and more than a typical change ({step[i]:.2g}), "
                        "so it is not measured. Raise --spp and --refinement-steps (the renders' "
                        "noise may dominate), add views that show it, tie channels or give a "
                        "prior.")
        for i, v in enumerate(values):
            hit = at_bound(float(v), lower, upper)
            if hit:
                checks.append(f"{name}[{i}] = {v:.4g} sits at its {hit}: the optimum lies at or "
                              "beyond it, so the standard error is no symmetric interval. If the "
                              "bound is physical (an absorption of 0: clear glass) the value may "
                              "be right; otherwise the model or the start is wrong.")
        checks += _noise_walk(name, entry, values, stderr, lower, upper)
        plausible = PLAUSIBLE_RANGES.get(kinds.get(name, ("", "")))
        if plausible is not None:
            outside = [(i, v) for i, v in enumerate(values) if not plausible[0] <= v <= plausible[1]]
            if outside:
                listed = ", ".join(f"{v:.4g}" for _, v in outside)
                checks.append(
                    f"{name} = {listed} is outside what a real {kinds[name][0]} has "
                    f"({plausible[0]:g} to {plausible[1]:g}): the fit most likely found a wrong "
                    "basin. Start closer (abs glass rgb gives physical values), tie the channels, "
                    "or fit at a coarser resolution first.")
    # Levenberg-Marquardt's refinement measures it; Adam's average of iterates does not (yet).
    if summary.get("method") == "lm" and summary.get("monte_carlo_points", 2) < 2:
        checks.append(
            "The standard errors count the photographs' noise only: the renders' Monte-Carlo error "
            "of the values, measured from the scatter of the refinement's points, needs at least "
            f"two points and this fit had {summary['monte_carlo_points']}, so the errors may be "
            "far too small. Fit with --refinement-steps 4 or more.")
    # A polish that could not put a scalar at the objective's minimum (polish.py) says why.
    for entry in summary.get("polish") or ():
        if entry.get("note"):
            checks.append(f"The polish of {entry['name']} (component {entry['component']}) did not "
                          f"reach the objective's minimum: {entry['note']}.")
    # Judged on the photographs' share of the covariance when the fit gives it: the refinement's
    # Monte-Carlo error moves the scalars together (an IOR's noisy steps carry every channel's
    # absorption with them), which the standard errors already hold and which says nothing of
    # what the photographs can tell apart (the glass suite's sphere-1.52 with 4096-spp
    # photographs: absorption channels correlated +0.99 in all, each measured to within 4 %).
    corr = summary.get("data_correlation") or summary.get("correlation") or {}
    labels, matrix = corr.get("names", []), corr.get("matrix", [])
    for i in range(len(labels)):
        for j in range(i + 1, len(labels)):
            c = matrix[i][j]
            if c is not None and abs(c) > TRADE_OFF_CORRELATION:
                checks.append(f"{labels[i]} and {labels[j]} trade off (correlation {c:+.3f}): the "
                              "photographs cannot tell them apart; their individual values are "
                              "uncertain far beyond their standard errors' look.")
    noise = summary.get("image_noise")
    holdout = (summary.get("holdout_rmse") or {}).get("after")
    reference, where = (holdout, "holdout") if holdout is not None else \
        ((summary.get("train_rmse") or {}).get("after"), "training")
    if noise and reference is not None and reference > HOLDOUT_NOISE_FACTOR * noise:
        checks.append(
            f"The {where} RMSE after the fit ({reference:.3g}) is {reference / noise:.1f} times the "
            f"photographs' noise ({noise:.3g}): the model does not explain the photographs. "
            "Physics may be missing (try abs diagnose), or the fit stopped in a wrong minimum.")
    return checks
