"""``abs sample SCENE CAPTURE --out DIR``: posterior of scene parameters by emcee, around a fit."""

from __future__ import annotations

import os
from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("sample", help="sample the posterior of scene parameters (emcee)")
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("capture", type=Path, help="capture folder (cameras.json)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--params", help="comma-separated parameter names (default: the scene's [fit])")
    p.add_argument("--from-fit", type=Path, metavar="FITDIR",
                   help="start around this fit (FITDIR/fit.json) instead of fitting first")
    p.add_argument("--walkers", type=int, default=0, help="ensemble size (default: max(8, 4 P))")
    p.add_argument("--spp", type=int, default=512,
                   help="samples per pixel of each of the two likelihood renders per view")
    p.add_argument("--downsample", type=int, default=2, help="compare images reduced by this factor")
    p.add_argument("--clamp", type=float, default=None, help="clamp renderings at this value")
    p.add_argument("--max-steps", type=int, default=5000, help="chain length cap (steps)")
    p.add_argument("--max-renders", type=int, default=None, help="render budget of the chain")
    p.add_argument("--draws", type=int, default=8, help="posterior draws rendered for the report")
    p.add_argument("--eval-spp", type=int, default=None,
                   help="samples per pixel of the posterior predictive renders (default: the scene's)")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="local worker processes for likelihood evaluations (1: this process; "
                        "default: 2, or 1 on a one-core machine)")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786): evaluate there")
    p.add_argument("--calibration-pairs", type=int, default=8,
                   help="further seed pairs at the mode that recentre the likelihood and "
                        "calibrate its render variance (0: off)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-reweight", action="store_true",
                   help="render the likelihood at every evaluation, even when every sampled "
                        "parameter reweights from path-length recordings")
    p.add_argument("--resume", action="store_true", help="continue the chain in OUT/chain.h5")
    p.add_argument("--no-report", action="store_true", help="skip the HTML report")
    p.set_defaults(run=run)


def _fmt(value, spec: str, width: int) -> str:
    return f"{'-' if value is None else format(value, spec):>{width}}"


def _table(summary) -> list[str]:
    lines = [f"{'parameter':<24} {'mean':>10} {'sd':>9} {'5 %':>10} {'95 %':>10} {'ESS':>7} {'truth':>9}"]
    for name, e in summary["parameters"].items():
        n = len(e["mean"])
        for i in range(n):
            label = name if n == 1 else f"{name}[{i}]"
            truth = e.get("truth", [None] * n)[i]
            lines.append(" ".join([f"{label:<24}", _fmt(e["mean"][i], ".5g", 10),
                                   _fmt(e["sd"][i], ".3g", 9), _fmt(e["q05"][i], ".5g", 10),
                                   _fmt(e["q95"][i], ".5g", 10), _fmt(e["ess"][i], ".0f", 7),
                                   _fmt(truth, ".5g", 9)]))
    lines.append(f"acceptance {summary['acceptance_fraction']:.2f}, {summary['steps']} steps x "
                 f"{summary['walkers']} walkers, burn-in {summary['burn_in']}, "
                 f"stop: {summary['stop_reason']}, renders {summary['renders']}")
    return lines


def run(args) -> int:
    from tqdm import tqdm

    from abs.errors import InputError
    from abs.sampling import SampleSettings, read_start, sample
    from abs.sampling.files import CHAIN_FILE, SUMMARY_FILE, write_sample_folder
    from abs.pools import worker_pool
    from abs.scene import load_scene
    from abs.simulate import read_truth

    settings = SampleSettings(spp=args.spp, downsample=args.downsample, clamp=args.clamp,
                              walkers=args.walkers, max_steps=args.max_steps,
                              max_renders=args.max_renders, predictive_draws=args.draws,
                              eval_spp=args.eval_spp, seed=args.seed,
                              calibration_pairs=args.calibration_pairs,
                              reweight=not args.no_reweight)
    if args.workers < 1:
        raise InputError(None, "--workers", f"must be >= 1, got {args.workers}")
    scene = load_scene(args.scene)
    names = [n.strip() for n in args.params.split(",") if n.strip()] if args.params else None
    chosen = names or list(scene.fit_parameters)
    start = read_start(args.from_fit, chosen) if args.from_fit else None
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    if args.resume and not (out / CHAIN_FILE).exists():
        print(f"no chain in {out}; starting a new one")

    bar = tqdm(total=settings.max_steps, desc="sample", unit="step")
    chain = {"first": False}

    def on_step(progress) -> None:
        if chain["first"]:
            # Rate and time left count the chain's steps only: not the stages before it, nor the
            # steps of a resumed file (the bar starts one step back from the first report).
            chain["first"] = False
            bar.total = progress.budget_steps or bar.total
            bar.n = bar.last_print_n = bar.initial = progress.steps - 1
        bar.update(progress.steps - bar.n)
        tau = "-" if progress.tau is None else f"{float(progress.tau.max()):.3g}"
        bar.set_postfix(acc=f"{progress.acceptance_fraction:.2f}", tau=tau)

    def on_stage(message: str) -> None:
        # The chain's own steps fill the bar; everything around it is named in its description.
        bar.set_description_str(f"sample [{message}]")
        if message == "chain":
            bar.reset()
            chain["first"] = True

    with worker_pool(args.workers, args.scheduler) as pool:
        result = sample(scene, args.capture, names, settings, out / CHAIN_FILE, start=start,
                        resume=args.resume, pool=pool, on_step=on_step, on_stage=on_stage,
                        truth=read_truth(args.capture, chosen))
    bar.close()
    summary = write_sample_folder(out, result, report=not args.no_report)
    if not args.no_report:
        print(f"report: {out / 'report' / 'report.html'}")
    print("\n".join(_table(summary)))
    for check in summary["checks"]:
        print(f"check: {check}")
    print(f"wrote {out / SUMMARY_FILE}")
    return 0
