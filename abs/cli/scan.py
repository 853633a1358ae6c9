"""``abs scan SCENE CAPTURE --param NAME --out DIR``: per-channel one-parameter RMSE scans."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("scan", help="scan one parameter channel by channel (the seeds' baseline)")
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("capture", type=Path, help="capture folder (cameras.json)")
    p.add_argument("--param", required=True, help="parameter name, e.g. glass.absorption")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--points", type=int, default=15, help="grid points per channel")
    p.add_argument("--range", help="LO,HI: scan this interval (default: around the scene's value)")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--downsample", type=int, default=2, help="compare images reduced by this factor")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-reweight", action="store_true",
                   help="render every grid point (the seeds' way) rather than reweighting one "
                        "path-length recording per view (absorption, environment scale)")
    p.set_defaults(run=run)


def run(args) -> int:
    import numpy as np
    from tqdm import tqdm

    from abs.fitting import scan
    from abs.report.figures import plot_scan
    from abs.runs.files import write_json
    from abs.simulate import read_truth

    grid = None
    if args.range:
        try:
            lo, hi = (float(x) for x in args.range.split(","))
        except ValueError:
            raise SystemExit(f"abs scan: error: --range {args.range!r}: expected LO,HI") from None
        grid = np.linspace(lo, hi, args.points)
    bar = tqdm(desc="scan", unit="point")
    result = scan(args.scene, args.capture, args.param, grid=grid, points=args.points, spp=args.spp,
                  downsample=args.downsample, seed=args.seed, on_point=lambda: bar.update(1),
                  reweight=not args.no_reweight)
    bar.close()
    summary = result.summary()
    write_json(args.out / "scan.json", summary)
    truth = read_truth(args.capture, [args.param])
    plot_scan(args.out / "scan.png", summary, truth[args.param] if truth else None)
    print(f"{args.param} minima: {', '.join(f'{v:.5g}' for v in result.minimum)} {result.unit}")
    print(f"wrote {args.out / 'scan.json'} and scan.png")
    return 0
