"""Gradient fit against the seeds' per-channel scan, on the same synthetic capture.

Simulates a noisy capture of the default scene (glass sphere on a tablecloth before a printed
checkerboard) with known absorption, then estimates ``glass.absorption`` three ways from the same
wrong start, in this one run:

- ``scan``: the seeds' method (``abs.scan`` with every grid point rendered, one channel at a time);
- ``fit_rendered``: ``abs.fit`` rendering every evaluation (Levenberg-Marquardt + Gauss-Newton
  refinement on fresh renders: the fit before path-length recordings);
- ``fit_recorded``: ``abs.fit`` from path-length recordings (``abs.render.path_lengths``): a
  recording per view and seed, reweighted at every evaluation, at ``--recorded-spp``.

Reports renders, camera samples (everything each call rendered, the fits' before/after images
included), wall time and the final relative error per channel, and the ratios to the recorded
fit. Writes ``benchmarks/results/fit_vs_scan.json``.

    python benchmarks/fit_vs_scan.py [--width 96 --height 72 --spp 16 --recorded-spp 4 --pairs 2 --points 15]
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
    p.add_argument("--recorded-spp", type=int, default=4,
                   help="samples per pixel of the recorded fit's recordings and images")
    p.add_argument("--pairs", type=int, default=2, help="the recorded fit's further seed pairs")
    args = p.parse_args()

    scene = load_scene(ROOT / "scenes/default/scene.toml").with_render(spp=32)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_scene(scene, tmp / "truth.toml", {"glass.absorption": TRUTH})
        write_scene(scene, tmp / "start.toml", {"glass.absorption": START})
        simulate_capture(load_scene(tmp / "truth.toml"), tmp / "capture", n_cameras=3,
                         width=args.width, height=args.height, spp=512, shot_noise=1e-4,
                         read_noise=0.003, seed=3)
        recorded = fit(tmp / "start.toml", tmp / "capture", ["glass.absorption"],
                       FitSettings(spp=args.recorded_spp, max_iterations=12,
                                   refinement_steps=args.pairs, eval_spp=args.recorded_spp))
        rendered = fit(tmp / "start.toml", tmp / "capture", ["glass.absorption"],
                       FitSettings(spp=args.spp, max_iterations=12, refinement_steps=4, reweight=False))
        scanned = scan(tmp / "start.toml", tmp / "capture", "glass.absorption", points=args.points,
                       spp=args.spp, downsample=1, grid=np.linspace(5.0, 50.0, args.points),
                       reweight=False)

    def fit_row(result):
        se = result.vector.split(result.uncertainty.stderr)["glass.absorption"]
        return {"renders": result.renders, "samples": result.samples_rendered,
                "wall_s": result.wall_s, "estimate": result.values["glass.absorption"].tolist(),
                "stderr": se.tolist()}

    rows = {
        "fit_recorded": fit_row(recorded),
        "fit_rendered": fit_row(rendered),
        "scan": {"renders": scanned.renders, "samples": scanned.samples_rendered,
                 "wall_s": scanned.wall_s, "estimate": scanned.minimum.tolist()},
    }
    for row in rows.values():
        row["relative_error"] = (np.abs(np.array(row["estimate"]) / TRUTH - 1)).tolist()
    base = rows["fit_recorded"]
    ratios = {f"{name}_over_recorded": {k: row[k] / base[k] for k in ("renders", "samples", "wall_s")}
              | {"max_relative_error": max(row["relative_error"]) / max(base["relative_error"])}
              for name, row in rows.items() if name != "fit_recorded"}

    print(f"truth {TRUTH.tolist()} 1/m, start {START.tolist()}, {args.width}x{args.height}, "
          f"{args.spp} spp (recorded fit: {args.recorded_spp})")
    print(f"{'method':13} {'renders':>8} {'samples':>12} {'wall s':>8}  estimate (relative error)")
    for name, row in rows.items():
        est = ", ".join(f"{e:.2f} ({r:.1%})" for e, r in zip(row["estimate"], row["relative_error"]))
        print(f"{name:13} {row['renders']:8d} {row['samples']:12d} {row['wall_s']:8.1f}  {est}")
    for name, r in ratios.items():
        print(f"{name}: " + ", ".join(f"{k} {v:.2f}" for k, v in r.items()))
    out = ROOT / "benchmarks/results/fit_vs_scan.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"machine": platform.platform(), "settings": vars(args),
                               "truth": TRUTH.tolist(), "rows": rows, "ratios": ratios}, indent=2))


if __name__ == "__main__":
    main()
