"""How much of a glass fit's error the photographs' own noise makes, measured over replicates.

A fit's Laplace standard errors take one noise level for all pixels. Whether that is right for the
glass suite's photographs (``benchmarks/glass_fit.py``: plain Mitsuba, sensor noise) is measured
here directly: ``--replicates`` photographs of one case's views (as the suite renders them, with
``--photo-glass-spp-factor`` times the samples where the glass is seen), differing only in their
render and noise seeds, and for each the Gauss-Newton step from the truth under renders of
``--render-spp`` samples (where the glass is seen, 4x; two independent renders for the image and
the Jacobian's cross curvature, the IOR's column by central differences with ``--ior-step``).
The steps' spread is the photographs' share of the estimate's error. Their mean is a bias of
abs's renderer against Mitsuba's at the truth plus one draw of the shared renders' noise, whose
size ``render_se`` estimates (half the difference of the two render seeds' mean steps). Beside
them, the homoscedastic Laplace part a fit would report
(``sigma^2`` from two independent 64-spp renders' residuals, as ``abs.fit`` takes it).

    python benchmarks/glass_photo_noise.py --case sphere-1.52 --replicates 8 --photo-spp 4096

Writes (adds to) ``benchmarks/results/glass_photo_noise.json``. Replicate captures are kept in
``--work`` and reused when their settings match.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from glass_fit import (CASES, FITTED, PHOTO_GLASS_SPP_FACTOR, ROOT, _scene_text,  # noqa: E402
                       mitsuba_photograph)

RESULTS = ROOT / "benchmarks/results/glass_photo_noise.json"
#: The suite's capture: its sensor noise and cameras (benchmarks/glass_fit.py, run_case).
CAPTURE = {"n_cameras": 5, "width": 120, "height": 100, "shot_noise": 1e-4, "read_noise": 0.003}
#: Compared as the glass recipe's fit compares: half resolution.
DOWNSAMPLE = 2


def _replicate(case, truth: Path, folder: Path, photo_spp: int, glass_factor: int,
               seed: int) -> Path:
    from abs.scene import load_scene
    from abs.simulate import simulate_capture

    wanted = {"spp": photo_spp, "glass_spp_factor": glass_factor, "seed": seed,
              **{k: CAPTURE[k] for k in ("shot_noise", "read_noise", "width", "height")},
              "elevation_deg": case.elevation_deg, "object_fraction": case.object_fraction}
    record = folder / "benchmark.json"  # simulate_capture's own record lacks the glass's factor
    if record.exists() and json.loads(record.read_text()) == wanted:
        return folder
    simulate_capture(load_scene(truth), folder, n_cameras=CAPTURE["n_cameras"],
                     width=CAPTURE["width"], height=CAPTURE["height"], spp=photo_spp,
                     shot_noise=CAPTURE["shot_noise"], read_noise=CAPTURE["read_noise"], seed=seed,
                     render=functools.partial(mitsuba_photograph, glass_spp_factor=glass_factor),
                     elevation_deg=case.elevation_deg,
                     object_fraction=case.object_fraction)
    record.write_text(json.dumps(wanted))
    return folder


def measure(case, work: Path, replicates: int, photo_spp: int, glass_factor: int,
            render_spp: int, ior_step: float) -> dict:
    from abs.model import build_model

    folder = work / case.name
    folder.mkdir(parents=True, exist_ok=True)
    truth = folder / "truth.toml"
    truth.write_text(_scene_text(case.mesh, [case.ior] * 3, case.absorption_per_m, case.env_scale))
    captures = []
    for k in range(replicates):
        t0 = time.perf_counter()
        name = f"photos-{photo_spp}" + (f"-glass{glass_factor}" if glass_factor > 1 else "")
        captures.append(_replicate(case, truth, folder / name / f"r{k}", photo_spp, glass_factor,
                                   100 + k))
        print(f"{case.name}: replicate {k} ready ({time.perf_counter() - t0:.0f} s)", flush=True)
    options = {"tied": ["glass.ior"], "glass_spp_factor": 4,
               "difference_steps": {"glass.ior": ior_step}}
    model = build_model(truth, captures[0], FITTED, **options)
    problem = model.problem("train", downsample=DOWNSAMPLE)
    theta = model.vector.initial.copy()

    def photographs(p) -> np.ndarray:
        return np.concatenate([o.photograph[o.mask].ravel() for o in p.observations])

    ra, Ja = problem.residuals(theta, render_spp, 501, jacobian=True, jacobian_seed=502)
    rb, Jb = problem.residuals(theta, render_spp, 503, jacobian=True, jacobian_seed=504)
    curvature = 0.5 * (Ja.T @ Jb + Jb.T @ Ja)
    jacobian = 0.5 * (Ja + Jb)
    # Each replicate's step from the truth under either seed's render, and under their mean: the
    # replicates share the renders, so the mean step holds one draw of the renders' Monte-Carlo
    # noise besides any bias, which the replicates' scatter does not show. Half the difference
    # of the two seeds' mean steps estimates that draw's standard deviation (one degree of freedom).
    per_seed = {seed: [] for seed in "ab"}
    for capture in captures:
        other = build_model(truth, capture, FITTED, **options).problem("train", downsample=DOWNSAMPLE)
        for seed, r in (("a", ra), ("b", rb)):
            image = photographs(problem) + r  # the render at the truth
            per_seed[seed].append(-np.linalg.solve(curvature, jacobian.T @ (image - photographs(other))))
    steps_a, steps_b = np.array(per_seed["a"]), np.array(per_seed["b"])
    steps = 0.5 * (steps_a + steps_b)
    # The Laplace part a fit reports: sigma^2 from two independent renders' residuals at 64 spp.
    r1, J1 = problem.residuals(theta, 64, 11, jacobian=True, jacobian_seed=12)
    r2 = problem.residuals(theta, 64, 13)[0]
    sigma2 = float(r1 @ r2) / (J1.shape[0] - J1.shape[1])
    laplace = np.sqrt(np.maximum(np.diag(np.linalg.inv(curvature)) * sigma2, 0.0))
    return {"case": case.name, "labels": model.vector.labels(), "replicates": replicates,
            "photo_spp": photo_spp, "photo_glass_spp_factor": glass_factor,
            "render_spp": render_spp, "ior_step": ior_step,
            "steps": steps.tolist(), "sd": steps.std(axis=0, ddof=1).tolist(),
            "mean": steps.mean(axis=0).tolist(),
            "mean_se": (steps.std(axis=0, ddof=1) / np.sqrt(replicates)).tolist(),
            "render_se": (0.5 * np.abs(steps_a.mean(axis=0) - steps_b.mean(axis=0))).tolist(),
            "laplace_sd": laplace.tolist(), "pixel_sigma": float(np.sqrt(max(sigma2, 0.0)))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="sphere-1.52")
    parser.add_argument("--replicates", type=int, default=8)
    parser.add_argument("--photo-spp", type=int, default=4096)
    parser.add_argument("--photo-glass-spp-factor", type=int, default=PHOTO_GLASS_SPP_FACTOR,
                        help="the photographs' samples where the glass is seen, as a multiple of "
                             "--photo-spp (1: before 2026-11-28)")
    parser.add_argument("--render-spp", type=int, default=512)
    parser.add_argument("--ior-step", type=float, default=0.08,
                        help="the IOR's central-difference step (the suite's pilot chose 0.08 for "
                             "sphere-1.52, 0.02 for sphere-1.62)")
    parser.add_argument("--work", type=Path, default=ROOT / "out/glass-photo-noise")
    parser.add_argument("--results", type=Path, default=RESULTS)
    args = parser.parse_args()
    case = next((c for c in CASES if c.name == args.case and not c.sensor), None)
    if case is None:
        parser.error(f"--case: one of {', '.join(c.name for c in CASES if not c.sensor)}")
    row = measure(case, args.work, args.replicates, args.photo_spp, args.photo_glass_spp_factor,
                  args.render_spp, args.ior_step)
    done = json.loads(args.results.read_text()) if args.results.exists() else []
    key = ("case", "photo_spp", "photo_glass_spp_factor")
    done = [r for r in done if [r.get(k, 1) for k in key] != [row[k] for k in key]]
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps(done + [row], indent=2))
    for label, sd, mean, se, rse, lap in zip(row["labels"], row["sd"], row["mean"], row["mean_se"],
                                             row["render_se"], row["laplace_sd"]):
        print(f"{label:24s} photographs' sd {sd:.3g}  mean step {mean:+.3g} +- {se:.2g} "
              f"(photographs) +- {rse:.2g} (renders)  Laplace part {lap:.3g}")


if __name__ == "__main__":
    main()
