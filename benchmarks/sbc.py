"""Simulation-based calibration of ``abs.sample``: coverage of the 50 % and 90 % intervals.

For each of N synthetic datasets a true glass absorption (1/m per RGB channel) is drawn uniformly
from [LO, HI], a noisy capture of a scene (``--scene``: the default scene, or the fast glass
sphere of ``sampling_data.py``) is simulated with it, ``abs.fit`` starts from a wrong value, and
``abs.sample`` samples around the fit. The rank of the truth among the posterior samples
(fraction below it) is recorded per channel; a calibrated posterior puts it inside the central
50 % interval half of the time and inside the 90 % interval 90 % of the time, and its ranks are
uniform (Kolmogorov-Smirnov p reported); ``z = (truth - mean) / sd`` has mean 0 and sd 1 (a
shifted, too-wide posterior can cover at the nominal rate: these show it). The posterior's prior
is flat (not the uniform draw), so this checks frequentist coverage of a likelihood-dominated
posterior. The photographs are rendered to convergence (``--photo-spp``): real photographs carry
no Monte-Carlo noise, and the noise model has no term for it. Results are written after every
dataset to ``benchmarks/results/sbc.json`` (``sbc_sphere.json`` for the sphere); ``--resume``
skips the datasets already there.

    python benchmarks/sbc.py [--scene sphere --datasets 4 --width 32 --height 24 --spp 512 --steps 30]
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats

from abs.fitting import FitSettings, fit
from abs.runs.files import write_json
from abs.sampling import SampleSettings, sample
from sampling_data import PARAMETER, make_dataset

RESULTS = Path(__file__).resolve().parent / "results" / "sbc.json"
#: Bumped when the sampler's likelihood changes, so that ``--resume`` does not mix datasets of
#: two samplers (2: one recentring offset per render, render variance of the K + 1 pairs' mean).
SAMPLER_REVISION = 2


def one_dataset(index: int, args) -> dict:
    rng = np.random.default_rng(1000 + index)
    truth = rng.uniform(args.lo, args.hi, size=3)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        capture = make_dataset(tmp, truth, args.width, args.height, seed=index,
                               photo_spp=args.photo_spp, scene=args.scene)
        fitted = fit(tmp / "scene.toml", capture, [PARAMETER],
                     FitSettings(spp=args.fit_spp, downsample=args.downsample, max_iterations=8,
                                 refinement_steps=2, seed=index),
                     initial={PARAMETER: [(args.lo + args.hi) / 2] * 3})
        entry = fitted.summary()["parameters"][PARAMETER]
        result = sample(tmp / "scene.toml", capture, [PARAMETER],
                        SampleSettings(spp=args.spp, downsample=args.downsample, walkers=args.walkers,
                                       max_steps=args.steps, predictive_draws=0, seed=index),
                        chain_path=tmp / "chain.h5",
                        start={PARAMETER: {"value": entry["value"], "stderr": entry["stderr"]}})
    flat = result.chain.reshape(-1, 3)
    rank = (flat < truth).mean(axis=0)
    summary = result.summary()
    return {"index": index, "truth": truth.tolist(), "fit": entry["value"], "fit_stderr": entry["stderr"],
            "mode": summary["parameters"][PARAMETER]["mode"],
            "mean": flat.mean(axis=0).tolist(), "sd": flat.std(axis=0).tolist(), "rank": rank.tolist(),
            "in50": ((rank > 0.25) & (rank < 0.75)).tolist(), "in90": ((rank > 0.05) & (rank < 0.95)).tolist(),
            "tau": summary["tau"], "acceptance_fraction": summary["acceptance_fraction"],
            "reduced_chi2_at_mode": summary["noise"]["reduced_chi2_at_mode"],
            "render_scale": summary["noise"]["render_scale"], "renders": summary["renders"],
            "wall_s": time.perf_counter() - t0}


def _dataset_se(per_channel: np.ndarray) -> float | None:
    """Standard error of the mean of ``per_channel`` (datasets x channels), from the scatter of
    the per-dataset means (``None`` with fewer than two datasets)."""
    means = per_channel.mean(axis=1)
    return float(means.std(ddof=1) / np.sqrt(means.size)) if means.size > 1 else None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--datasets", type=int, default=4)
    p.add_argument("--scene", choices=("default", "sphere"), default="default",
                   help="default scene or the fast glass sphere (results in results/sbc_sphere.json)")
    p.add_argument("--width", type=int, default=32)
    p.add_argument("--height", type=int, default=24)
    p.add_argument("--downsample", type=int, default=2)
    p.add_argument("--spp", type=int, default=512, help="samples per pixel of the sampler's renders")
    p.add_argument("--fit-spp", type=int, default=64, help="samples per pixel of the starting fit")
    p.add_argument("--photo-spp", type=int, default=16384, help="samples per pixel of the photographs")
    p.add_argument("--walkers", type=int, default=8)
    p.add_argument("--steps", type=int, default=30)
    p.add_argument("--lo", type=float, default=2.0)
    p.add_argument("--hi", type=float, default=10.0)
    p.add_argument("--resume", action="store_true", help="keep datasets already in the results file")
    args = p.parse_args()
    config = {k: v for k, v in vars(args).items() if k not in ("datasets", "resume")}
    config["sampler_revision"] = SAMPLER_REVISION

    results = RESULTS if args.scene == "default" else RESULTS.with_name(f"sbc_{args.scene}.json")
    done = []
    if args.resume and results.exists():
        saved = json.loads(results.read_text())
        if saved.get("config") == config:
            done = saved["datasets"]
    for index in range(len(done), args.datasets):
        done.append(one_dataset(index, args))
        in50 = np.array([d["in50"] for d in done], float)
        in90 = np.array([d["in90"] for d in done], float)
        ranks = np.ravel([d["rank"] for d in done])
        z = np.ravel([(np.array(d["truth"]) - d["mean"]) / np.array(d["sd"]) for d in done])
        report = {"config": config, "parameter": PARAMETER, "datasets": done,
                  "coverage_50": float(in50.mean()), "coverage_90": float(in90.mean()),
                  # Coverage alone can hide a shifted, too-wide posterior: uniform ranks and
                  # z = (truth - mean) / sd with mean 0 and sd 1 are the sharper checks.
                  "rank_ks_pvalue": float(stats.kstest(ranks, "uniform").pvalue),
                  "z_mean": float(z.mean()), "z_sd": float(z.std(ddof=1)) if z.size > 1 else None,
                  # A dataset's channels share light paths (their misses are correlated), so
                  # standard errors treat datasets, not channel intervals, as the independent units.
                  "coverage_50_se": _dataset_se(in50), "coverage_90_se": _dataset_se(in90),
                  "z_mean_se": _dataset_se(z.reshape(len(done), -1)),
                  "coverage_50_per_channel": in50.mean(axis=0).tolist(),
                  "coverage_90_per_channel": in90.mean(axis=0).tolist(),
                  "intervals_checked": int(in50.size), "machine": platform.platform()}
        write_json(results, report)
        d = done[-1]
        print(f"dataset {index}: truth {np.round(d['truth'], 2)} mean {np.round(d['mean'], 2)} "
              f"sd {np.round(d['sd'], 2)} rank {np.round(d['rank'], 2)} ({d['wall_s']:.0f} s)", flush=True)
    n = report["intervals_checked"]
    print(f"\n{'interval':<10} {'coverage':>9} {'nominal':>8}   ({n} channel intervals, "
          f"{len(done)} datasets)")
    for level in (50, 90):
        print(f"{level:>3} %      {report[f'coverage_{level}']:>9.2f} {level / 100:>8.2f}")
    print("standard errors over datasets (a dataset's channels are correlated): "
          f"90 %: {report['coverage_90_se'] or float('nan'):.2f}, "
          f"50 %: {report['coverage_50_se'] or float('nan'):.2f}")
    print(f"ranks against uniform: KS p = {report['rank_ks_pvalue']:.2g}; z = (truth - mean) / sd: "
          f"mean {report['z_mean']:.2f} +- {report['z_mean_se'] or float('nan'):.2f} (0 if unbiased), "
          f"sd {report['z_sd'] or float('nan'):.2f} (1 if calibrated)")
    print(f"wrote {results}")


if __name__ == "__main__":
    main()
