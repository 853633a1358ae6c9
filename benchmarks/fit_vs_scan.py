"""Gradient fit against the seeds' per-channel scan, on the same synthetic capture.

Simulates a noisy capture of the default scene (glass sphere on a tablecloth before a printed
checkerboard) with known absorption, then estimates ``glass.absorption`` twice from the same wrong
start: ``abs.fit`` (Levenberg-Marquardt + refinement) and ``abs.scan`` (per-channel RMSE scans).
Reports renders used, camera samples, wall time and the final relative error per channel, and the
ratios scan / fit, all measured in this one run. Writes ``benchmarks/results/fit_vs_scan.json``.

    python benchmarks/fit_vs_scan.py [--width 96 --height 72 --spp 16 --points 15]
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
from pathlib import Path

import numpy as np

from abs.fitting import FitSettings, fit, scan
from abs.scene import load_scene
from abs.scene.write import write_scene
from abs.simulate import simulate_capture

ROOT = Path(__file__).resolve().parents[1]
TRUTH = np.array([30.0, 12.0, 20.0])  # 1/m: a strongly tinted glass, visible at this resolution
START = np.array([20.0, 20.0, 20.0])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=int, default=96)
    p.add_argument("--height", type=int, default=72)
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of both methods' renders")
    p.add_argument("--points", type=int, default=15, help="scan grid points per channel")
    args = p.parse_args()

    scene = load_scene(ROOT / "scenes/default/scene.toml").with_render(spp=32)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_scene(scene, tmp / "truth.toml", {"glass.absorption": TRUTH})
        write_scene(scene, tmp / "start.toml", {"glass.absorption": START})
        simulate_capture(load_scene(tmp / "truth.toml"), tmp / "capture", n_cameras=3,
                         width=args.width, height=args.height, spp=512, shot_noise=1e-4,
                         read_noise=0.003, seed=3)
        fitted = fit(tmp / "start.toml", tmp / "capture", ["glass.absorption"],
                     FitSettings(spp=args.spp, max_iterations=12, refinement_steps=4))
        scanned = scan(tmp / "start.toml", tmp / "capture", "glass.absorption", points=args.points,
                       spp=args.spp, downsample=1, grid=np.linspace(5.0, 50.0, args.points))

    rows = {
        "fit": {"renders": fitted.renders, "samples": fitted.samples_rendered,
                "wall_s": fitted.wall_s, "estimate": fitted.values["glass.absorption"].tolist()},
        "scan": {"renders": scanned.renders, "samples": scanned.samples_rendered,
                 "wall_s": scanned.wall_s, "estimate": scanned.minimum.tolist()},
    }
    for row in rows.values():
        row["relative_error"] = (np.abs(np.array(row["estimate"]) / TRUTH - 1)).tolist()
    ratios = {k: rows["scan"][k] / rows["fit"][k] for k in ("renders", "samples", "wall_s")}
    ratios["max_relative_error"] = max(rows["scan"]["relative_error"]) / max(rows["fit"]["relative_error"])

    print(f"truth {TRUTH.tolist()} 1/m, start {START.tolist()}, {args.width}x{args.height}, {args.spp} spp")
    print(f"{'method':6} {'renders':>8} {'samples':>12} {'wall s':>8}  estimate (relative error)")
    for name, row in rows.items():
        est = ", ".join(f"{e:.2f} ({r:.1%})" for e, r in zip(row["estimate"], row["relative_error"]))
        print(f"{name:6} {row['renders']:8d} {row['samples']:12d} {row['wall_s']:8.1f}  {est}")
    print("ratios scan / fit: " + ", ".join(f"{k} {v:.2f}" for k, v in ratios.items()))
    out = ROOT / "benchmarks/results/fit_vs_scan.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": platform.platform(), "settings": vars(args),
                               "truth": TRUTH.tolist(), "rows": rows, "ratios": ratios}, indent=2))


if __name__ == "__main__":
    main()
