"""``abs fit SCENE CAPTURE --out DIR``: fit parameters, write fit.json, the fitted scene, a report."""

from __future__ import annotations

from pathlib import Path


def _optimisers() -> tuple[str, ...]:
    """The registered optimisers' names: their files in abs/fitting/optimisers/ (see its
    ``names``), listed without importing abs.fitting, which would start the renderer for --help."""
    from importlib.resources import files

    folder = files("abs").joinpath("fitting", "optimisers")
    return tuple(sorted(f.name[:-3] for f in folder.iterdir()
                        if f.name.endswith(".py") and not f.name.startswith("_")))


def add_parser(sub) -> None:
    p = sub.add_parser("fit", help="fit scene parameters to a capture's photographs")
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("capture", type=Path, help="capture folder (cameras.json)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--params", help="comma-separated parameter names (default: the scene's [fit])")
    p.add_argument("--init", action="append", default=[], metavar="NAME=V[,V...]",
                   help="start a parameter here instead of at the scene's value (repeatable), "
                        "e.g. --init glass.absorption=2,2,2")
    p.add_argument("--method", choices=("auto", *_optimisers()), default="auto",
                   help="Levenberg-Marquardt (few scalars) or Adam (many); auto picks")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of fitting renders")
    p.add_argument("--downsample", type=int, default=1, help="compare images reduced by this factor")
    p.add_argument("--clamp", type=float, default=None,
                   help="clamp renderings at this value (photographs that saturate, e.g. 1.0)")
    p.add_argument("--max-iterations", type=int, default=20)
    p.add_argument("--refinement-steps", type=int, default=4,
                   help="Gauss-Newton steps on independent renders after Levenberg-Marquardt "
                        "(from path-length recordings: further independent seed pairs)")
    p.add_argument("--refinement-spp", type=int, default=None,
                   help="samples per pixel of the refinement's renders (default: --spp)")
    p.add_argument("--learning-rate", type=float, default=0.05, help="Adam step (typical steps)")
    p.add_argument("--spp-schedule", default="", help="Adam: ITER:SPP,... e.g. 0:4,20:16")
    p.add_argument("--downsample-schedule", default="", help="coarse to fine, Adam and LM: ITER:FACTOR,... e.g. 0:4,10:2,20:1")
    p.add_argument("--eval-spp", type=int, default=None,
                   help="samples per pixel of the before/after renders (default: the scene's)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tie", action="append", default=[], metavar="NAME",
                   help="fit this per-channel parameter as one value for all channels "
                        "(e.g. glass.ior when the photographs do not resolve dispersion); repeatable")
    p.add_argument("--no-reweight", action="store_true",
                   help="render every evaluation, even when all fitted parameters reweight from "
                        "path-length recordings (absorption, environment scale, sensor)")
    p.add_argument("--starts", action="append", default=[], metavar="NAME=V1,V2,...",
                   help="several starts: a short fit from each value (every channel), the full fit "
                        "from the best end; for an IOR before a textured backdrop, e.g. "
                        "glass.ior=1.45,1.55,1.65,1.75 (repeatable: every combination)")
    p.add_argument("--glass-spp-factor", type=int, default=1, metavar="F",
                   help="F times the samples per pixel where glass is seen (its refractions are the "
                        "images' noisiest part and measure its IOR); default 1")
    p.add_argument("--difference-steps", default=None, metavar="auto|NAME=H,...",
                   help="central-difference steps of parameters that take their derivative so (an "
                        "IOR): 'auto' chooses each from a pilot of its Jacobian column; "
                        "glass.ior=0.04 gives it; default: the parameter's own")
    p.add_argument("--polish-spp", type=int, default=None, metavar="SPP",
                   help="after the optimiser, a last parabola along the objective itself for "
                        "parameters whose derivative is a central difference (an IOR), rendered "
                        "at SPP samples per pixel; default: none")
    p.add_argument("--polish-pairs", type=int, default=2,
                   help="with --polish-spp: seed pairs the polish averages (their scatter is its "
                        "Monte-Carlo error); default 2")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.json")
    p.add_argument("--no-report", action="store_true", help="skip the HTML report")
    p.set_defaults(run=run)


def _initial(items: list[str]) -> dict:
    from abs.errors import InputError

    out = {}
    for item in items:
        name, _, values = item.partition("=")
        try:
            out[name.strip()] = [float(v) for v in values.split(",")]
        except ValueError:
            raise InputError(None, "--init", f"{item!r}: expected NAME=V[,V...] with numbers") from None
    return out


def run(args) -> int:
    import numpy as np
    from tqdm import tqdm

    from abs.fitting import FitSettings, OptimizerState, fit
    from abs.errors import InputError
    from abs.fitting.settings import parse_difference_steps, parse_schedule, parse_starts
    from abs.report.text import summary_lines
    from abs.runs.files import load_checkpoint, save_checkpoint
    from abs.runs.fit_folder import FIT_FILE, write_fit_folder
    from abs.runs.identity import run_identity
    from abs.simulate import read_truth
    from abs.scene import load_scene

    try:
        starts = parse_starts(args.starts)
    except ValueError as exc:
        raise InputError(None, "--starts", str(exc)) from None
    try:
        steps = parse_difference_steps(args.difference_steps)
    except ValueError as exc:
        raise InputError(None, "--difference-steps", str(exc)) from None
    settings = FitSettings(
        method=args.method, spp=args.spp, downsample=args.downsample, clamp=args.clamp,
        max_iterations=args.max_iterations, refinement_steps=args.refinement_steps,
        learning_rate=args.learning_rate, spp_schedule=parse_schedule(args.spp_schedule),
        downsample_schedule=parse_schedule(args.downsample_schedule), eval_spp=args.eval_spp,
        seed=args.seed, tie=tuple(args.tie), reweight=not args.no_reweight, starts=starts,
        glass_spp_factor=args.glass_spp_factor, difference_steps=steps,
        refinement_spp=args.refinement_spp, polish_spp=args.polish_spp,
        polish_pairs=args.polish_pairs)
    scene = load_scene(args.scene)
    names = [n.strip() for n in args.params.split(",") if n.strip()] if args.params else None
    initial = _initial(args.init)
    # Extending a fit (more iterations) is a resume, not a different fit.
    identity = run_identity(scene, args.capture, names or scene.fit_parameters, settings, initial=initial,
                            drop=("max_iterations", "refinement_steps", "polish_spp", "polish_pairs"))
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    resume = None
    if args.resume:
        saved = load_checkpoint(out, identity)
        if saved is None:
            print(f"no checkpoint in {out}; starting a new fit")
        else:
            resume = OptimizerState.from_dict(saved)
            print(f"resuming after iteration {resume.iteration}")

    if starts and resume is None:
        count = int(np.prod([len(v) for _, v in starts]))
        print(f"several starts: {count} short fits first ("
              + "; ".join(f"{n} = {', '.join(f'{x:g}' for x in v)}" for n, v in starts) + ")",
              flush=True)
    total = settings.max_iterations + (settings.refinement_steps if settings.method != "adam" else 0)
    bar = tqdm(total=total, desc="fit", unit="it", initial=resume.iteration if resume else 0)

    def on_iteration(state) -> None:
        save_checkpoint(out, identity, state.to_dict())
        bar.total = max(bar.total, state.iteration)
        bar.update(state.iteration - bar.n)
        loss = state.history[-1]["loss"]  # None: a trial whose renders were not finite
        bar.set_postfix(rmse="non-finite trial" if loss is None else f"{loss:.4g}")

    result = fit(scene, args.capture, names, settings, initial=initial, resume=resume, on_iteration=on_iteration,
                 truth=read_truth(args.capture, names or scene.fit_parameters))
    bar.close()

    summary = write_fit_folder(out, scene, result, report=not args.no_report)
    if not args.no_report:
        print(f"report: {out / 'report' / 'report.html'}")
    print("\n".join(summary_lines(summary)))
    for check in summary.get("checks", []):
        print(f"check: {check}")
    print(f"wrote {out / FIT_FILE}")
    return 0
