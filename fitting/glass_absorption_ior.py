"""Fit a glass's absorption and refractive index, with the environment's scale, in one run.

When to use it: a clear or tinted glass object of known shape, under known lighting (an
environment map of known shape but uncertain brightness), seen before a textured backdrop such as
the seeds' printed checkerboard, whose colour (absorption, 1/m per R, G, B) and refractive index
are to be measured. The settings are those of the glass suite (``benchmarks/glass_fit.py``:
captures rendered by plain Mitsuba, never by abs; the README's table), which this recipe's
``SETTINGS`` define.

Why these settings:

- **One IOR for all channels** (``tie``): glass disperses by about 0.01 between red and blue,
  which photographs of this kind do not resolve; three noisy channels would each be barely
  constrained. Fit ``<material>.ior`` untied with ``abs fit`` when the data show dispersion.
- **Coarse to fine** (``downsample_schedule``): a checkerboard seen through a sphere moves by
  more than a square when the IOR is 0.02 off, and a Gauss-Newton model of the sharp image then
  predicts little; box-averaged images (factor 4, then 2) find the basin.
- **On the CPU 64 spp to find the basin, then 12 refinement steps at 256 spp; on a GPU 256
  spp and 16 steps**: renders through glass are noisy (fireflies); the fit's objective is
  unbiased by that noise (two fixed-seed renders, ``docs/fitting.md``), and the refinement's
  fresh renders average it out and measure it (the standard errors include it). What is left is
  the noise of the estimate itself, which the refinement's samples decide: with 16 steps at 64
  spp the glass suite's framed bowl fitted IOR 1.539 +- 0.022 (its steps a random walk, as its
  check said), with 12 at 256 spp 1.5171 +- 0.0035 and absorption 6.12, 2.39, 0.92 per metre
  for 1.52 and 6, 2.5, 1, in 8.6 min on 2 cores (6.1 min before): a step's Newton target
  through a thin wall is far less noisy at four times the samples, while Levenberg-Marquardt
  only has to find the basin (``REFINEMENT``). On an H100 the fit at 256 spp takes about a
  minute (IOR 1.5181 +- 0.0047, absorption 6.24, 2.52, 0.94).
- **Four times the samples where the glass is seen** (``glass_spp_factor``): its refractions
  are the noisiest pixels and what the IOR is measured by; the rectangle around the glass costs
  a fraction of the image (``docs/fitting.md``).
- **The IOR's difference step chosen per scene** (``difference_steps="auto"``): its derivative
  is a central difference whose noise falls as the step grows, while its signal holds only as
  long as the image is near linear over the step; a pilot of the column at 1, 2 and 4 times the
  IOR's own step (0.02) keeps the least noisy step that keeps the signal (the glass suite's
  spheres: 0.02 to 0.08; a thin-walled bowl: 0.08; :mod:`abs.model.difference_steps`).
- **A last parabola along the objective** (``POLISH``, :mod:`abs.fitting.polish`): the
  refinement's IOR column is a secant over twice that step, whose fixed point is not the
  objective's minimum where the image is nonlinear over it and the model not exact (the glass
  suite's clear sphere: 1.4721 for 1.47, 2.8 standard errors); the polish evaluates the objective
  itself at the fitted IOR and a fifth of the step either side and moves the IOR to the
  parabola's vertex (the absorption and scale with it as far as they correlate): 1.4697 +- 0.0002
  there. It costs about two minutes on a sphere, three on the suite's framed bowl, whose
  thin-walled objective is not convex over the offsets (the polish keeps the value and says so).
- **The environment's scale with them**: a brighter environment and a clearer glass trade off
  on the glass's pixels; every other pixel pins the scale.
- **Several starts** (``FitSettings.starts``, :mod:`abs.fitting.starts`): the IOR's objective
  has more than one basin (a checkerboard seen through a sphere matches itself at more than one
  magnification: sphere-1.47 of the glass suite, started at IOR 1.75, ended at 1.646 +- 0.007
  with no check). Short coarse fits from IORs across real glasses (1.45 to 1.75) end in their
  basins, and the full fit starts from the end with the lowest two-seed objective averaged over
  fresh seed pairs at four times the samples (``abs fit --starts glass.ior=...`` does the same).

What it assumes: geometry, cameras and the environment's shape are right; the glass's IOR lies
in 1.4 to 1.8 (``--starts`` otherwise; ``--starts none`` starts at the scene's values, which then
must be a sensible start: IOR within about 0.1); any absorption. A
Gaussian prior in the scene's ``[fit.priors]`` is used when present. A fit that failed says so
(``check:`` lines: an IOR outside real glasses, a parameter at a bound, a holdout residual far
above the noise).

Writes the fit folder ``DIR`` (fit.json, scene.toml, renders/, report/).

Usage::

    python fitting/glass_absorption_ior.py SCENE CAPTURE --out DIR [--material glass] [--no-scale]
        [--starts 1.45,1.55,1.65,1.75]
"""

from __future__ import annotations

import abs
from abs.render.variant import current_backend
from abs.scene import load_scene
from common import fit_stage, parser

#: The glass suite's settings (benchmarks/glass_fit.py runs this recipe's settings), less spp
#: and the refinement's.
SETTINGS = dict(glass_spp_factor=4, downsample=2, downsample_schedule=((0, 4), (6, 2)), max_iterations=20,
                difference_steps="auto")
#: Samples per pixel by Dr.Jit backend: on a GPU four times the CPU's samples still fit in about a
#: minute, and they halve the estimate's Monte-Carlo noise.
SPP = {"llvm": 64, "cuda": 256}
#: The refinement's steps and samples per pixel by backend (None: ``SPP``'s). On 2 cores its 12
#: steps at 256 spp cost about 2.5 more minutes than 16 at 64 and cut the framed bowl's IOR
#: error from 0.019 to 0.003 (one run each; the module's docstring).
REFINEMENT = {"llvm": dict(refinement_steps=12, refinement_spp=256),
              "cuda": dict(refinement_steps=16, refinement_spp=None)}
#: The polish's samples per pixel by backend, and its seed pairs: after the refinement, a last
#: parabola along the objective itself puts the IOR at the objective's minimum (the refinement's
#: central differences have their own fixed point where the image is nonlinear in the IOR: the
#: glass suite's clear sphere fitted 1.4721 for 1.47). On 2 cores three pairs at 1024 spp take
#: about two minutes on the suite's spheres, and single pairs' vertices scatter by 0.0003 to
#: 0.0013 there (offsets a fifth of the chosen difference step either side). The GPU's 4096 spp
#: is not yet measured.
POLISH = {"llvm": dict(polish_spp=1024, polish_pairs=3), "cuda": dict(polish_spp=4096, polish_pairs=3)}
#: IORs the short fits start from: real glasses' range (abs.fitting.checks.PLAUSIBLE_RANGES,
#: 1.45 to 1.8) in steps of 0.1, about the width of a basin at the coarse stage.
IOR_STARTS = (1.45, 1.55, 1.65, 1.75)


def settings(material: str = "glass", starts=IOR_STARTS) -> abs.FitSettings:
    """The recipe's :class:`abs.FitSettings` for the glass material ``material``, with short fits
    from the IORs ``starts`` first (``None`` or empty: from the scene's values only); spp by the
    active variant's backend (``SPP``, ``REFINEMENT``, ``POLISH``)."""
    backend = current_backend()
    return abs.FitSettings(**SETTINGS, **REFINEMENT[backend], **POLISH[backend], spp=SPP[backend],
                           tie=(f"{material}.ior",),
                           starts=((f"{material}.ior", tuple(starts)),) if starts else ())


def parameters(material: str = "glass", scale: bool = True) -> list[str]:
    """The fitted parameters: absorption, IOR and (unless ``scale`` is false) the environment's
    scale."""
    return [f"{material}.absorption", f"{material}.ior"] + (["environment.scale"] if scale else [])


def main(argv=None) -> int:
    """Run the recipe on ``argv`` (default: the command line); returns the exit status."""
    p = parser(__doc__)
    p.add_argument("--material", default="glass", help="name of the glass material in the scene")
    p.add_argument("--no-scale", action="store_true",
                   help="hold the environment's scale at the scene's value")
    p.add_argument("--starts", default=",".join(map(str, IOR_STARTS)),
                   help="IORs of the short fits that choose the start (comma-separated), or "
                        "'none' to start at the scene's values")
    args = p.parse_args(argv)
    starts = None
    if args.starts != "none":
        try:
            starts = [float(x) for x in args.starts.split(",")]
        except ValueError:
            p.error(f"--starts: expected comma-separated IORs or 'none', got {args.starts!r}")
        if not all(1.0 < x < 3.0 for x in starts):
            p.error(f"--starts: IORs must lie between 1 and 3, got {args.starts!r}")
    scene = load_scene(args.scene)
    names = parameters(args.material, not args.no_scale)
    fit_stage(scene, args.capture, names, settings(args.material, starts), args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
