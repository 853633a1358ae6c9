"""``abs capture build BUILD.json --out CAPTURE``: photographs + darks + calibration -> capture.

The build file format is in :mod:`abs.acquisition.build`. ``--report DIR`` writes each view's
HDR weight map (total exposure time used per pixel) and, for raw views, its noise relative to
its value (``<name>_noise.png``) as PNG. ``--demosaic bilinear|superpixel``
overrides the build file's ``demosaic`` (default bilinear; superpixel halves the resolution).
"""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("capture", help="make capture folders from real photographs")
    kinds = p.add_subparsers(dest="kind", required=True)
    q = kinds.add_parser("build", help="demosaic, subtract darks, merge brackets, undistort and "
                                       "write cameras.json plus EXRs")
    q.add_argument("build_file", type=Path, help="build file (JSON) listing views and frames")
    q.add_argument("--out", type=Path, required=True, help="capture folder to write")
    q.add_argument("--report", type=Path, help="folder for the HDR weight maps and noise maps")
    q.add_argument("--demosaic", choices=("bilinear", "superpixel"), default=None,
                   help="demosaicing method, overriding the build file's 'demosaic' (default "
                        "bilinear): 'superpixel' makes one RGB pixel of each 2x2 CFA cell, no "
                        "interpolation, a half-size capture with the half-resolution camera")
    q.set_defaults(run=run)


def run(args) -> int:
    from tqdm import tqdm

    from abs.acquisition.build import build_capture
    from abs.acquisition.figures import write_noise_png, write_weight_png
    from abs.errors import read_json

    # Read first only to size the progress bar; a bad file fails here with build_capture's error.
    views = read_json(args.build_file, what="build file").get("views")
    total = len(views) if isinstance(views, list) else None
    with tqdm(total=total, desc="build", unit="view") as bar:
        capture, merges = build_capture(args.build_file, args.out, progress=bar.update,
                                        demosaic=args.demosaic)
    for name, merged in merges.items():
        n_sat = int(merged.saturated_everywhere.sum())
        used = merged.used.reshape(merged.used.shape[0], -1).mean(axis=1)
        print(f"{name}: frames used on " + ", ".join(f"{100 * u:.0f} %" for u in used)
              + " of pixels" + (f"; {n_sat} values saturated in every frame (lower bounds)"
                                if n_sat else ""))
        if args.report:
            args.report.mkdir(parents=True, exist_ok=True)
            write_weight_png(args.report / f"{name}_weight.png", merged.weight)
            view = capture.view(name)
            if view.noise is not None:
                write_noise_png(args.report / f"{name}_noise.png", view.read_image(),
                                view.read_noise())
    blur = capture.views[0].blur_px
    print("processing (demosaicing, undistortion): written per view; fits render the sensor "
          "sites and apply the build's weights")
    print(f"processing blur (blur_px, for readers without it): R {blur[0]:.2f}, "
          f"G {blur[1]:.2f}, B {blur[2]:.2f} px")
    print(f"wrote {len(capture.views)} views to {args.out}")
    return 0
