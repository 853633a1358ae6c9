"""Fit the environment map's brightness (``environment.scale``) alone.

When to use it: the lighting's shape is known (a measured or captured environment map) but not
its absolute level relative to the photographs, e.g. an HDR map captured at another exposure, or
photographs whose exposure changed. Run it first, before fitting materials: a wrong brightness
would otherwise be absorbed into whatever material parameters are fitted.

What it assumes: geometry, cameras and materials in the scene file are right; photographs are
linear (no tone curve) and unsaturated. The scale multiplies every pixel that the environment
lights, so thousands of pixels constrain one number: the fit compares images at half resolution
(``downsample=2``) with few samples per pixel, which keeps it cheap without losing precision.

Usage::

    python fitting/environment_scale.py SCENE CAPTURE --out DIR
"""

from __future__ import annotations

import abs
from abs.scene import load_scene
from common import fit_stage, parser

# Levenberg-Marquardt on a single scalar converges in a handful of evaluations; the Gauss-Newton
# refinement on fresh renders removes the bias that the low spp would otherwise leave.
SETTINGS = dict(spp=8, downsample=2, max_iterations=10, refinement_steps=4)


def main(argv=None) -> int:
    """Run the recipe on ``argv`` (default: the command line); returns the exit status."""
    args = parser(__doc__).parse_args(argv)
    fit_stage(load_scene(args.scene), args.capture, ["environment.scale"],
              abs.FitSettings(**SETTINGS), args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
