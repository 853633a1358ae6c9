"""Fit a glass's absorption, then its refractive index and absorption together (two stages).

When to use it: a clear or tinted glass object of known shape, under known lighting, whose
colour (absorption, 1/m per R, G, B) and refractive index (per R, G, B) are to be measured.

Why two stages: absorption changes the brightness of the light through the glass smoothly and
almost independently per channel, so it converges from a poor start. The index of refraction
moves the refracted image and trades off against absorption (a different index changes the path
lengths inside the glass); fitted jointly from a poor absorption, Levenberg-Marquardt can settle
in a wrong valley. Stage 1 fits ``<material>.absorption`` with the index held at the scene's
value; stage 2 starts from stage 1's fitted scene and fits ``<material>.ior`` and
``<material>.absorption`` together, with more samples per pixel because the index's gradients are
noisier.

What it assumes: geometry, cameras and environment (including its scale: run
``environment_scale.py`` first) are right; the scene's ``ior`` is a sensible start (within a few
hundredths, e.g. 1.5 for soda-lime glass). A Gaussian prior on the index in the scene's
``[fit.priors]`` is used when present. Limitations (docs/renderer.md, "Known limitations"):
index fits are biased by up to about 0.01 even for glass against the environment alone, and edges
seen *through* the glass (a textured backdrop behind it) are not differentiated, which biases the
index further or stalls stage 2; compare stage 2's holdout RMSE with stage 1's. Glass renders
are noisy, and so are the refinement steps: when the values in stage 2's report (parameter plot)
still jump between the last steps, the printed standard errors understate the error; refit with
``abs fit`` at higher ``--spp`` and more ``--refinement-steps``.

Writes ``DIR/stage1`` and ``DIR/stage2`` (each: fit.json, scene.toml, renders/, report/); the
final result is ``DIR/stage2/scene.toml``.

Usage::

    python fitting/glass_absorption_ior.py SCENE CAPTURE --out DIR [--material glass]
"""

from __future__ import annotations

import abs
from abs.scene import load_scene
from common import fit_stage, parser

# Levenberg-Marquardt settles within a few evaluations on these few scalars; the Gauss-Newton
# refinement on fresh renders then removes the Monte-Carlo bias of that point, which for glass
# (noisy caustics) is large: more refinement steps, and for stage 2, more samples per pixel.
STAGE1 = dict(spp=16, max_iterations=8, refinement_steps=6)
STAGE2 = dict(spp=32, max_iterations=8, refinement_steps=10)


def main(argv=None) -> int:
    """Run the recipe on ``argv`` (default: the command line); returns the exit status."""
    p = parser(__doc__)
    p.add_argument("--material", default="glass", help="name of the glass material in the scene")
    args = p.parse_args(argv)

    absorption, ior = f"{args.material}.absorption", f"{args.material}.ior"
    fit_stage(load_scene(args.scene), args.capture, [absorption], abs.FitSettings(**STAGE1),
              args.out / "stage1")
    # The fitted scene file of stage 1 is the start of stage 2.
    fit_stage(load_scene(args.out / "stage1" / "scene.toml"), args.capture, [ior, absorption],
              abs.FitSettings(**STAGE2), args.out / "stage2")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
