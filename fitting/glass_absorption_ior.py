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
- **64 spp, 16 refinement steps**: renders through glass are noisy (fireflies); the fit's
  objective is unbiased by that noise (two fixed-seed renders, ``docs/fitting.md``), and the
  refinement's fresh renders average it out and measure it (the standard errors include it).
- **The environment's scale with them**: a brighter environment and a clearer glass trade off
  on the glass's pixels; every other pixel pins the scale.

What it assumes: geometry, cameras and the environment's shape are right; the scene's values are
a sensible start (IOR within about 0.1, e.g. 1.5 for soda-lime glass; any absorption). A
Gaussian prior in the scene's ``[fit.priors]`` is used when present. A fit that failed says so
(``check:`` lines: an IOR outside real glasses, a parameter at a bound, a holdout residual far
above the noise).

Writes the fit folder ``DIR`` (fit.json, scene.toml, renders/, report/).

Usage::

    python fitting/glass_absorption_ior.py SCENE CAPTURE --out DIR [--material glass] [--no-scale]
"""

from __future__ import annotations

import abs
from abs.scene import load_scene
from common import fit_stage, parser

#: The glass suite's settings (benchmarks/glass_fit.py runs this recipe's settings).
SETTINGS = dict(spp=64, downsample=2, downsample_schedule=((0, 4), (6, 2)), max_iterations=20,
                refinement_steps=16)


def settings(material: str = "glass") -> abs.FitSettings:
    """The recipe's :class:`abs.FitSettings` for the glass material ``material``."""
    return abs.FitSettings(**SETTINGS, tie=(f"{material}.ior",))


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
    args = p.parse_args(argv)
    fit_stage(load_scene(args.scene), args.capture, parameters(args.material, not args.no_scale),
              settings(args.material), args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
