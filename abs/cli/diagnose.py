"""``abs diagnose SCENE CAPTURE --out DIR``: fit the scene, find what physics it leaves out, write
``diagnosis.json`` and a report."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("diagnose", help="find the physics a scene file leaves out (fit, locate the "
                                        "misfit, test the catalogue of effects, refit)")
    p.add_argument("scene", type=Path, help="scene file (TOML); its [fit] parameters are the baseline")
    p.add_argument("capture", type=Path, help="capture folder (cameras.json) with a holdout view")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of fitting renders")
    p.add_argument("--downsample", type=int, default=2, help="compare images reduced by this factor")
    p.add_argument("--max-effects", type=int, default=2, help="stop after this many accepted effects")
    p.add_argument("--max-iterations", type=int, default=10, help="Levenberg-Marquardt evaluations per fit")
    p.add_argument("--refinement-steps", type=int, default=3,
                   help="Gauss-Newton steps on independent renders after each fit")
    p.add_argument("--eval-spp", type=int, default=None,
                   help="samples per pixel of the before/after renders (default: the scene's)")
    p.add_argument("--effects", default=None,
                   help="comma-separated effects to consider (default: the whole catalogue)")
    p.add_argument("--clamp", type=float, default=None,
                   help="clamp renderings at this value (photographs that saturate, e.g. 1.0)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-report", action="store_true", help="skip the HTML report")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted diagnosis from the checkpoints in OUT/models")
    p.set_defaults(run=run)


def run(args) -> int:
    from tqdm import tqdm

    from abs.diagnosis import diagnose
    from abs.fitting import FitSettings
    from abs.report.diagnosis_report import write_diagnosis_report
    from abs.runs.files import write_json

    settings = FitSettings(spp=args.spp, downsample=args.downsample, clamp=args.clamp,
                           max_iterations=args.max_iterations, refinement_steps=args.refinement_steps,
                           eval_spp=args.eval_spp, seed=args.seed)
    only = [e.strip() for e in args.effects.split(",") if e.strip()] if args.effects else None
    args.out.mkdir(parents=True, exist_ok=True)
    bar = tqdm(desc="diagnose", unit="step")

    def on_step(message: str) -> None:
        bar.set_postfix_str(message)
        bar.update(1)

    result = diagnose(args.scene, args.capture, settings, max_effects=args.max_effects, only=only,
                      work_dir=args.out / "models", on_step=on_step, resume=args.resume)
    bar.close()
    path = write_json(args.out / "diagnosis.json", result.to_json())
    if not args.no_report:
        print(f"report: {write_diagnosis_report(args.out / 'report', result)}")
    base = result.baseline
    print(f"baseline: train RMSE {base.rmse('train'):.4g}, holdout RMSE {base.rmse('holdout'):.4g}")
    for s in result.candidates:
        print(f"  candidate {s.candidate.label}: score {s.statistic:.1f} ({s.method}, {s.dof} dof), "
              f"predicted BIC gain {s.predicted_bic_gain:.1f}")
    for f in result.findings:
        print(f"found {f.candidate.effect}: {f.comparison.holdout_measure} "
              f"{f.comparison.holdout_rmse_before:.4g} -> "
              f"{f.comparison.holdout_rmse_after:.4g}. {f.explanation}")
    print(f"verdict: {', '.join(result.verdict) or 'nothing missing'}")
    print(f"wrote {path}")
    return 0
