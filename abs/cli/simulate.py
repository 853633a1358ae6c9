"""``abs simulate SCENE --cameras N --out CAPTURE``: a synthetic capture with known truth."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("simulate", help="make a synthetic capture folder of a scene")
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("--cameras", type=int, default=4, help="number of views")
    p.add_argument("--out", type=Path, required=True, help="capture folder to write")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--fov", type=float, default=30.0, help="vertical field of view, degrees")
    p.add_argument("--spp", type=int, default=512, help="samples per pixel of the photographs")
    p.add_argument("--holdout", type=int, default=None,
                   help="number of holdout views (default: 1 when there are 3 or more views)")
    p.add_argument("--shot-noise", type=float, default=0.0,
                   help="photon noise: variance per unit of linear intensity")
    p.add_argument("--read-noise", type=float, default=0.0, help="sensor read noise, std. dev.")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(run=run)


def run(args) -> int:
    from tqdm import tqdm

    from abs.simulate import simulate_capture
    from abs.scene import load_scene

    scene = load_scene(args.scene)
    bar = tqdm(total=args.cameras, desc="simulate", unit="view")
    capture = simulate_capture(
        scene, args.out, n_cameras=args.cameras, width=args.width, height=args.height,
        fov_deg=args.fov, spp=args.spp, n_holdout=args.holdout, shot_noise=args.shot_noise,
        read_noise=args.read_noise, seed=args.seed, on_view=lambda name: bar.update(1))
    bar.close()
    print(f"wrote {len(capture.views)} views to {args.out}")
    return 0
