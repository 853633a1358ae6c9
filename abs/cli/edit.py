"""``abs edit``: give the object in one HDR photograph a new material (docs/editing.md).

    abs edit PHOTO --mask MASK --to MATERIAL --out DIR

writes to DIR: ``edited.exr`` (linear) and ``edited.png`` (tone-mapped at the photograph's
exposure), the estimates it was made from (``background.exr``, ``environment.exr`` — a lat-long map
in abs's convention, usable as a scene's environment —, ``depth.exr``, ``normals.png``,
``highlights.png``) and ``edit.json`` (material, method, settings, highlight threshold, and for
``--method synthesis`` the fit's residual and values: ``trust``; ``environment.exr`` is then the
fitted map).
"""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    from abs.editing.spec import GRAMMAR

    p = sub.add_parser("edit", help="image-based material editing of an object in an HDR photograph")
    p.add_argument("photo", type=Path, help="linear HDR photograph (.exr or .hdr)")
    p.add_argument("--mask", type=Path, required=True,
                   help="the object's mask (same size; nonzero = object; must not touch the border)")
    p.add_argument("--to", required=True, help=f"target material: {GRAMMAR}")
    p.add_argument("--out", type=Path, required=True, help="folder to write the results to")
    p.add_argument("--method", default="baseline",
                   help="baseline (Khan et al. 2006; default) or synthesis (analysis by synthesis: "
                        "fit the photograph with abs's renderer, render the new material)")
    p.add_argument("--fov", type=float, default=24.0,
                   help="synthesis: the photograph's vertical field of view, degrees "
                        "(default %(default)s)")
    p.add_argument("--spp", type=int, default=64,
                   help="synthesis: samples per pixel of the final renderings (default %(default)s)")
    p.add_argument("--samples", type=int, default=400,
                   help="environment directions per pixel for merl:NAME (default %(default)s)")
    p.add_argument("--reshape", type=int, default=1,
                   help="applications of the gradient-boosting spline, 1 to 4 (default %(default)s)")
    p.add_argument("--merl-dir", help="folder of real MERL .binary files (default: the shared fits)")
    p.add_argument("--seed", type=int, default=0, help="seed of the environment directions")
    p.set_defaults(run=run_edit)


def run_edit(args) -> int:
    import json

    import numpy as np

    from abs.colour.tonemap import auto_exposure
    from abs.editing import EditSettings, edit
    from abs.errors import InputError
    from abs.io.images import write_exr, write_mask, write_png

    if args.samples < 1:
        raise InputError(None, "--samples", f"must be at least 1, got {args.samples}")
    if not 0 <= args.reshape <= 4:
        raise InputError(None, "--reshape", f"expected 0 to 4 (the paper: 1 to 4), got {args.reshape}")
    import abs.resynthesis  # registers the synthesis method  # noqa: F401
    from abs.resynthesis import SynthesisSettings

    if not 0 < args.fov < 180:
        raise InputError(None, "--fov", f"expected degrees in (0, 180), got {args.fov}")
    if args.spp < 1:
        raise InputError(None, "--spp", f"must be at least 1, got {args.spp}")
    settings = EditSettings(samples=args.samples, reshape_times=args.reshape, seed=args.seed,
                            merl_dir=args.merl_dir,
                            synthesis=SynthesisSettings(fov_deg=args.fov, render_spp=args.spp,
                                                        seed=args.seed))
    try:
        result = edit(args.photo, args.mask, args.to, args.method, settings=settings)
    except InputError as exc:
        if exc.field in ("to", "method"):  # name the command's options, not the API's arguments
            raise InputError(exc.source, f"--{exc.field}", exc.message) from exc
        raise
    out = args.out
    if out.exists() and not out.is_dir():
        raise InputError(out, "--out", "exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    from abs.io.images import read_image

    exposure = auto_exposure(read_image(args.photo))
    write_exr(out / "edited.exr", result.image)
    write_png(out / "edited.png", result.image, exposure)
    write_exr(out / "background.exr", result.background)
    write_exr(out / "environment.exr", result.environment)
    write_exr(out / "depth.exr", np.repeat(result.depth[..., None], 3, axis=2))
    normals = np.where(result.mask[..., None], (result.normals + 1.0) * 0.5, 0.0)
    write_png(out / "normals.png", np.round(normals * 255).astype(np.uint8))
    write_mask(out / "highlights.png", result.highlights)
    summary = {"photo": str(args.photo), "mask": str(args.mask), "material": str(result.material),
               "method": args.method, "highlight_threshold": result.highlight_threshold,
               "object_pixels": int(result.mask.sum()),
               "highlight_pixels": int(result.highlights.sum()),
               "settings": {k: (vars(v) if k == "synthesis" and v is not None else v)
                            for k, v in vars(result.settings).items()},
               # The synthesis fit's residual against the photograph's noise: how far to trust it.
               "trust": result.trust}
    (out / "edit.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    if result.trust is not None:
        print(f"abs edit: fit residual {result.trust['residual_rmse']:.4g} = "
              f"{result.trust['noise_ratio']:.1f} x the photograph's noise")
        left_out = result.trust.get("highlight_pixels_left_out", 0)
        if left_out:
            # A sun's highlight: the fit could not use it, so the light's level rests on the rest.
            print(f"abs edit: {left_out} pixels of a sharp highlight left out of the fit "
                  f"(a sun the smooth fitted light cannot hold)")
        sun = result.trust.get("highlight")
        if sun is not None and result.trust.get("roughness_from") == "highlight":
            rmse = ", ".join(f"{r}: {v:.3g}" for r, v in sun["rmse"].items())
            print(f"abs edit: roughness {result.trust['roughness']:g} from a sun fitted to that "
                  f"highlight (its RMSE per candidate roughness: {rmse})")
    print(f"abs edit: {result.material} ({args.method}) -> {out}")
    return 0
