"""Render and render+gradient time of the default scene at two resolutions.

Prints a table and writes ``benchmarks/results/render_speed.json``. Times are the median of
``--repeats`` runs after one warm-up run (which compiles the kernels); Dr.Jit launches are
asynchronous, so every timing reads the result back.

    python benchmarks/render_speed.py [--spp 16] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from abs.render import Camera, compile_scene
from abs.scene import load_scene
from abs.simulate import place_cameras

ROOT = Path(__file__).resolve().parents[1]


def _time(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--sizes", default="64x48,128x96")
    args = parser.parse_args()
    compiled = compile_scene(load_scene(ROOT / "scenes/default/scene.toml"))
    rows = []
    for size in args.sizes.split(","):
        w, h = map(int, size.split("x"))
        view = place_cameras(compiled, 1, w, h)[0]
        camera = Camera(view["K"], view["R"], view["t"], w, h)

        def render():
            compiled.render(camera, spp=args.spp).numpy()

        def render_grad():
            x = mi.Float(compiled.get("glass.absorption").astype(np.float32))
            dr.enable_grad(x)
            compiled.set("glass.absorption", x)
            dr.backward(dr.mean(compiled.render(camera, spp=args.spp), axis=None))
            dr.grad(x).numpy()
            compiled.set("glass.absorption", dr.detach(x))

        t_render, t_grad = _time(render, args.repeats), _time(render_grad, args.repeats)
        rows.append({"width": w, "height": h, "spp": args.spp, "render_s": t_render,
                     "render_and_gradient_s": t_grad, "gradient_over_render": t_grad / t_render})
    print(f"{'size':>9} {'spp':>4} {'render s':>9} {'render+grad s':>14} {'ratio':>6}")
    for r in rows:
        print(f"{r['width']:>4}x{r['height']:<4} {r['spp']:>4} {r['render_s']:>9.3f} "
              f"{r['render_and_gradient_s']:>14.3f} {r['gradient_over_render']:>6.2f}")
    big, small = rows[-1], rows[0]
    print(f"time ratio {big['width']}x{big['height']} / {small['width']}x{small['height']}: "
          f"render {big['render_s'] / small['render_s']:.2f}, "
          f"render+grad {big['render_and_gradient_s'] / small['render_and_gradient_s']:.2f}")
    out = ROOT / "benchmarks/results"
    out.mkdir(parents=True, exist_ok=True)
    record = {"variant": mi.variant(), "machine": platform.machine(), "rows": rows}
    (out / "render_speed.json").write_text(json.dumps(record, indent=2))
    print(f"saved {out / 'render_speed.json'}")


if __name__ == "__main__":
    main()
