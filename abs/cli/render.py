"""``abs render SCENE CAPTURE --out DIR``: render every view of a capture folder."""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render every view of a capture folder at the scene's settings")
    p.add_argument("scene", type=Path, help="scene file (TOML)")
    p.add_argument("capture", type=Path, help="capture folder with cameras.json")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--spp", type=int, help="override [render] spp")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(run=run)


def run(args) -> int:
    from abs.io.capture import load_capture
    from abs.io.images import write_exr, write_png
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    scene = load_scene(args.scene)
    capture = load_capture(args.capture)
    compiled = compile_scene(scene)
    args.out.mkdir(parents=True, exist_ok=True)
    for view in tqdm(capture.views, desc="render", unit="view"):
        image = compiled.render(Camera.from_view(view), spp=args.spp, seed=args.seed).numpy()
        write_exr(args.out / f"{view.name}.exr", image)
        write_png(args.out / f"{view.name}.png", image)
    print(f"wrote {len(capture.views)} views to {args.out}")
    return 0
