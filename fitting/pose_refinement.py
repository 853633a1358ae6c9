"""Refine an object's pose (``<object>.pose``) so that its silhouettes match the photographs.

When to use it: the object's placement in the scene file comes from a rough measurement (a
ruler, a marker) and is off by millimetres to a couple of centimetres or a few degrees, which
shows as outlines that do not line up in the error images. Fit the pose before fitting
materials: a misplaced object makes any material fit compensate for the wrong pixels.

The pose is a correction on top of the object's ``to_world`` (docs/conventions.md):
``[tx, ty, tz]`` in metres and a rotation vector ``[rx, ry, rz]`` (axis times angle, radians)
about the object's centroid, all six fitted together.

What it assumes: cameras and the rest of the scene are right; the object's outline is seen
against a background of different brightness in at least two training views (one view cannot
tell depth from size); the start is close (the fit is local: it follows the gradient of the
silhouette edges). Rotations that barely change the images (a sphere about any axis, a cylinder
about its own) are poorly determined and wander during the fit; hold them with a Gaussian prior
on the pose in the scene's ``[fit.priors]`` (e.g. ``mean = 0``, ``sd = [1, 1, 1, 0.01, 0.01,
0.01]``: translations free, rotations within about half a degree). Limitations
(docs/renderer.md): shadow boundaries and outlines seen through glass or in reflections are not
differentiated, and pose gradients of glass objects are very noisy. Edge sampling makes every
evaluation much slower than in a material fit.

Usage::

    python fitting/pose_refinement.py SCENE CAPTURE --object NAME --out DIR
"""

from __future__ import annotations

import abs
from abs.scene import load_scene
from common import fit_stage, parser

# Silhouette gradients come from pixels along edges only, so they are noisier than those of
# material parameters: more samples per pixel, full resolution (a downsampled image blurs the
# outline) and more refinement steps to average the Monte-Carlo noise out. Each evaluation costs
# six derivative renders per view (one per pose scalar), so iterations are kept few:
# Levenberg-Marquardt settles within about five from a start a centimetre off.
SETTINGS = dict(spp=32, downsample=1, max_iterations=10, refinement_steps=6)


def main(argv=None) -> int:
    """Run the recipe on ``argv`` (default: the command line); returns the exit status."""
    p = parser(__doc__)
    p.add_argument("--object", required=True, help="name of the object in the scene's [[objects]]")
    args = p.parse_args(argv)
    fit_stage(load_scene(args.scene), args.capture, [f"{args.object}.pose"],
              abs.FitSettings(**SETTINGS), args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
