"""Settings of a fit (what to compare, how to optimise), with defaults for small problems."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FitSettings", "schedule_value", "parse_schedule", "parse_starts",
           "parse_difference_steps", "explicit_steps"]

# Levenberg-Marquardt's Jacobian costs one forward-mode pass per scalar; beyond this many scalars
# Adam on reverse-mode gradients is cheaper.
LM_MAX_SCALARS = 16


def parse_schedule(text: str) -> tuple[tuple[int, int], ...]:
    """``"0:4,10:16"`` -> ``((0, 4), (10, 16))``: from iteration 0 use 4, from 10 use 16."""
    pairs = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        start, _, value = item.partition(":")
        try:
            pairs.append((int(start), int(value)))
        except ValueError:
            raise ValueError(f"schedule entry {item!r}: expected ITERATION:VALUE (integers)") from None
    return tuple(sorted(pairs))


def schedule_value(schedule: tuple[tuple[int, int], ...], iteration: int, default: int) -> int:
    """The value of a schedule at ``iteration`` (``default`` before its first entry)."""
    value = default
    for start, v in schedule:
        if iteration >= start:
            value = v
    return value


@dataclass(frozen=True)
class FitSettings:
    """How a fit compares and optimises.

    Attributes
    ----------
    method : str
        A registered optimiser (``abs/fitting/optimisers/``: ``lm``, ``adam``), or ``auto``:
        Levenberg-Marquardt up to ``LM_MAX_SCALARS`` fitted scalars, else Adam.
    spp : int
        Samples per pixel of the fitting renders (Adam: unless ``spp_schedule`` says otherwise).
    downsample : int
        Compare images box-averaged by this factor (renders at the reduced resolution).
    clamp : float or None
        Clamp renderings at this value before comparing (photographs that saturate).
    max_iterations : int
        Levenberg-Marquardt evaluations or Adam steps.
    learning_rate : float
        Adam's step in the unconstrained coordinates (about ``learning_rate`` typical steps).
    spp_schedule, downsample_schedule : tuple of (iteration, value)
        Coarse-to-fine schedules, e.g. ``((0, 4), (20, 16))``: Adam's spp and resolution;
        Levenberg-Marquardt's resolution stages (``lm_stages``; its refinement compares at
        ``downsample``).
    eval_spp : int or None
        Samples per pixel of the before/after renders of all views (default: the scene's).
    rtol, atol : float
        Levenberg-Marquardt's termination tolerances (unconstrained coordinates).
    refinement_steps : int
        Gauss-Newton steps on decorrelated renders after Levenberg-Marquardt (removes the bias
        that Monte-Carlo noise puts into a least-squares fit of one noisy render; 0: none).
        Not run when every fitted parameter reweights from path-length recordings (absorption,
        environment scale, sensor): raise ``spp`` instead, which those fits pay once.
    refinement_spp : int or None
        Samples per pixel of the Gauss-Newton refinement's renders (default: ``spp``; fits
        wholly from path-length recordings use ``spp`` for their seed pairs). The refinement's
        estimate is an average of Newton targets whose noise is the renders'; where a column is
        far noisier than its signal (an IOR seen through thin glass), fewer steps of more
        samples average better than many of few (the steps' curvature and trust radius are
        themselves noisy), and Levenberg-Marquardt, which only has to find the basin, keeps the
        cheaper ``spp``.
    seed : int
        Base seed of all renders.
    reweight : bool
        Render from path-length recordings when every fitted parameter reweights (glass
        absorption, environment scale, sensor; :mod:`abs.render.path_lengths`): a render per seed
        and view, however many evaluations. ``False``: render every evaluation.
    tie : tuple of str
        Per-channel parameters fitted as one value for all channels (``("glass.ior",)``: an IOR
        whose dispersion the photographs do not resolve; three noisy channels would each be
        barely constrained).
    starts : tuple of (str, tuple of float)
        Several starts (:mod:`abs.fitting.starts`): ``(("glass.ior", (1.45, 1.55, 1.65, 1.75)),)``
        runs a short fit from each value (set for every channel; several parameters: every
        combination), and the full fit starts where the best one ended. For an objective with
        more than one basin (an IOR seen through a sphere before a checkerboard). Empty: one
        start.
    glass_spp_factor : int
        Pixels where glass is seen (the rectangle around its objects' projected bounding boxes)
        take this many times ``spp``: their refractions are the noisiest part of the images
        and what an IOR is measured by (:class:`abs.render.camera.SampleBoost`). 1: none.
    difference_steps : "auto" or tuple of (str, float)
        The central-difference steps of parameters that take their derivative so (an IOR, in
        its units): ``"auto"`` chooses each from a pilot of its Jacobian column at the start
        (:mod:`abs.model.difference_steps`; recorded in ``fit.json``); pairs
        ``(("glass.ior", 0.04),)`` give them; empty: each parameter's own.
    polish_spp : int or None
        After the optimiser, a last step along the objective itself for every scalar whose
        derivative is a central difference (an IOR): the vertex of a parabola through the
        two-seed objective at the estimate and a fifth of its difference step either side
        (:mod:`abs.fitting.polish`), rendered at this many samples per pixel. ``None``: no
        polish.
    polish_pairs : int
        Seed pairs the polish averages (each renders two images per view at three values);
        their scatter is the polished scalar's Monte-Carlo error.
    """

    method: str = "auto"
    spp: int = 16
    downsample: int = 1
    clamp: float | None = None
    max_iterations: int = 20
    learning_rate: float = 0.05
    spp_schedule: tuple[tuple[int, int], ...] = ()
    downsample_schedule: tuple[tuple[int, int], ...] = ()
    eval_spp: int | None = None
    rtol: float = 1e-4
    atol: float = 1e-6
    refinement_steps: int = 4
    refinement_spp: int | None = None
    seed: int = 0
    tie: tuple[str, ...] = ()
    reweight: bool = True
    starts: tuple[tuple[str, tuple[float, ...]], ...] = ()
    glass_spp_factor: int = 1
    difference_steps: str | tuple[tuple[str, float], ...] = ()
    polish_spp: int | None = None
    polish_pairs: int = 2

    def __post_init__(self):
        from abs.fitting.optimisers import names

        known = ("auto", *names())
        if self.method not in known:
            raise ValueError(f"method must be {', '.join(known[:-1])} or {known[-1]}, "
                             f"not {self.method!r}")
        if self.spp < 1 or self.downsample < 1 or self.max_iterations < 1 or self.glass_spp_factor < 1:
            raise ValueError("spp, downsample, max_iterations and glass_spp_factor must be >= 1")
        if self.refinement_spp is not None and self.refinement_spp < 1:
            raise ValueError(f"refinement_spp must be >= 1 or None, not {self.refinement_spp}")
        if self.polish_spp is not None and self.polish_spp < 1:
            raise ValueError(f"polish_spp must be >= 1 or None, not {self.polish_spp}")
        if self.polish_pairs < 1:
            raise ValueError(f"polish_pairs must be >= 1, not {self.polish_pairs}")
        for entry in self.starts:
            if (len(entry) != 2 or not isinstance(entry[0], str) or not len(entry[1])
                    or not all(np.isfinite(float(v)) for v in entry[1])):
                raise ValueError(f"starts: expected (parameter name, (value, ...)), got {entry!r}")
        if isinstance(self.difference_steps, str):
            if self.difference_steps != "auto":
                raise ValueError(f"difference_steps must be 'auto' or (name, step) pairs, not "
                                 f"{self.difference_steps!r}")
        else:
            for entry in self.difference_steps:
                if (len(entry) != 2 or not isinstance(entry[0], str)
                        or not (np.isfinite(float(entry[1])) and float(entry[1]) > 0.0)):
                    raise ValueError(f"difference_steps: expected (parameter name, step > 0), "
                                     f"got {entry!r}")

    def resolved_method(self, n_scalars: int) -> str:
        if self.method != "auto":
            return self.method
        return "lm" if n_scalars <= LM_MAX_SCALARS else "adam"


def parse_starts(items) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """``["glass.ior=1.45,1.55"]`` -> ``(("glass.ior", (1.45, 1.55)),)`` (the command line's
    ``--starts``)."""
    out = []
    for item in items:
        name, _, values = item.partition("=")
        try:
            numbers = tuple(float(v) for v in values.split(","))
        except ValueError:
            numbers = ()
        if not name.strip() or not numbers or not all(np.isfinite(numbers)):
            raise ValueError(f"--starts {item!r}: expected NAME=V1,V2,... (numbers)")
        out.append((name.strip(), numbers))
    return tuple(out)


def parse_difference_steps(text: str | None):
    """``"auto"`` -> ``"auto"``, ``"glass.ior=0.04"`` -> ``(("glass.ior", 0.04),)``, ``None`` ->
    ``()`` (the command line's ``--difference-steps``)."""
    if text is None:
        return ()
    if text.strip() == "auto":
        return "auto"
    out = []
    for item in text.split(","):
        name, _, value = item.partition("=")
        try:
            step = float(value)
        except ValueError:
            step = float("nan")
        if not name.strip() or not np.isfinite(step) or step <= 0.0:
            raise ValueError(f"--difference-steps {item!r}: expected auto or NAME=STEP with a "
                             "positive step")
        out.append((name.strip(), step))
    return tuple(out)


def explicit_steps(settings: FitSettings) -> dict[str, float] | None:
    """``settings.difference_steps`` as a mapping for :func:`abs.model.build_model` (``None``
    for ``"auto"``: the model keeps the parameters' own steps until :func:`abs.fitting.fit`'s
    pilot sets its choice)."""
    if isinstance(settings.difference_steps, str):
        return None
    return {name: float(step) for name, step in settings.difference_steps}
