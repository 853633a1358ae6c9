"""Reconstruction error of held-out measured BRDFs against the number of observed direction pairs.

For each held-out material (not in the basis' training set: the leave-one-out protocol of the
seeds) and each n in 1, 2, 5, 10, 20, 50, 100, draws n random direction pairs (ωi and ωo uniform in
solid angle on the hemisphere with θ <= 80°), reads the true BRDF at the nearest table entries
(R, G, B; optionally with relative noise), reconstructs the full table with
:func:`abs.brdf.reconstruct.fit_coefficients` (η from :func:`default_eta`, and a few multiples of
it for comparison) and scores it against the true table; and the same for the first n of 100
direction pairs planned by :func:`abs.brdf.design.plan_directions` (chosen once, from the basis
alone, among ``--candidates`` random pairs), once per criterion (``mapped``, ``radiance``). Errors are averaged over pairs of
directions (the measure of :func:`abs.brdf.directions.merl_entry_measure`, estimated on a fixed
random subset of entries drawn in proportion to it), not over table entries, a third of which lie
within 10° of the specular direction:

- mapped RMSE: RMS of x̂ − x in the basis' log-relative mapping (what the PCA minimises);
- relative cosine-weighted RMSE: ‖w·(f̂ − f)‖ / ‖w·f‖ with w = cosθi·cosθo (reflected radiance);
- also, for comparison, the mapped RMSE averaged over table entries (``mapped_rmse_entries``).

Two references: the mean table (c = 0, what n = 0 gives) and the best table the basis holds
(:func:`project_table`, all entries). Writes ``benchmarks/results/brdf_reconstruction.json`` and
``.png``.

    python benchmarks/brdf_reconstruction.py [--basis basis.npz] [--draws 10] [--noise 0.0]

Without ``--basis`` a 32-component basis without the study materials is built (about 20 minutes
the first time on two busy cores; the tables are cached) and kept in the abs cache folder.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from abs.brdf.basis import BRDFBasis
from abs.brdf.design import CRITERIA, plan_directions
from abs.brdf.directions import merl_entries, merl_entry_measure, uniform_hemisphere_directions
from abs.brdf.measured import STUDY_MATERIALS, measured_material_names, measured_table
from abs.brdf.pca import build_basis
from abs.brdf.reconstruct import default_eta, fit_coefficients, project_table
from abs.io.shared_data import cache_dir

ROOT = Path(__file__).resolve().parents[1]
N_OBSERVATIONS = (1, 2, 5, 10, 20, 50, 100)
ETA_FACTORS = (0.0, 0.1, 1.0, 10.0)  # multiples of the default η; 1 is the default
MAX_THETA = np.radians(80.0)


def default_basis(components: int = 32) -> Path:
    path = cache_dir("brdf") / f"basis-k{components}-without-study.npz"
    if not path.is_file():
        names = [n for n in measured_material_names() if n not in STUDY_MATERIALS]
        build_basis(names, measured_table, components).save(path)
    return path


def quartiles(scores: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Median and quartiles of each metric over draws."""
    return {metric: {"median": float(np.median([d[metric] for d in scores])),
                     "q25": float(np.quantile([d[metric] for d in scores], 0.25)),
                     "q75": float(np.quantile([d[metric] for d in scores], 0.75))}
            for metric in scores[0]}


class Scorer:
    """Errors of reconstructions on fixed subsets of above-horizon entries (x̂_S = x̄_S + c·Q_S):
    ``pairs`` drawn in proportion to the direction-pair measure, ``entries`` uniformly."""

    def __init__(self, basis: BRDFBasis, truth: np.ndarray, pairs: np.ndarray, entries: np.ndarray):
        self.basis = basis
        x = basis.mapped(truth)
        self.parts = {}
        for key, subset in (("pairs", pairs), ("entries", entries)):
            self.parts[key] = dict(
                q=basis.components[:, subset].astype(np.float64), mean=basis.mean[subset].astype(np.float64),
                median=basis.median[subset].astype(np.float64), w=basis.cosine_weight[subset].astype(np.float64),
                f=truth.reshape(-1)[subset].astype(np.float64), x=x[subset])

    def __call__(self, c: np.ndarray) -> dict[str, float]:
        p, e = self.parts["pairs"], self.parts["entries"]
        x_hat = p["mean"] + c @ p["q"]
        eps = self.basis.epsilon
        f_hat = np.maximum(((p["median"] * p["w"] + eps) * np.exp(x_hat) - eps) / p["w"], 0.0)
        return {
            "mapped_rmse": float(np.sqrt(np.mean((x_hat - p["x"]) ** 2))),
            "relative_cosine_rmse": float(np.linalg.norm(p["w"] * (f_hat - p["f"]))
                                          / np.linalg.norm(p["w"] * p["f"])),
            "mapped_rmse_entries": float(np.sqrt(np.mean((e["mean"] + c @ e["q"] - e["x"]) ** 2))),
        }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--basis", type=Path, help="basis .npz (default: build/reuse a cached one)")
    p.add_argument("--materials", default=",".join(STUDY_MATERIALS), help="held-out materials")
    p.add_argument("--draws", type=int, default=10, help="random direction sets per n")
    p.add_argument("--noise", type=float, default=0.0, help="relative noise of the observed values")
    p.add_argument("--candidates", type=int, default=20_000,
                   help="random candidate pairs the planned directions are chosen from")
    p.add_argument("--subset", type=int, default=200_000, help="table entries scored (per subset)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=ROOT / "benchmarks/results/brdf_reconstruction.json")
    args = p.parse_args()

    start = time.perf_counter()
    basis_path = args.basis or default_basis()
    basis = BRDFBasis.load(basis_path)
    materials = [m for m in args.materials.split(",") if m]
    trained = set(basis.materials.tolist()) if basis.materials is not None else set()
    if trained & set(materials):
        raise SystemExit(f"not held out (in the basis' training set): {sorted(trained & set(materials))}")
    eta = default_eta(basis, args.noise)
    rng = np.random.default_rng(args.seed)
    # The planned rows' noise has its own stream, so that they leave the random rows' draws alone.
    planned_rng = np.random.default_rng(args.seed + 2)
    plans = {criterion: plan_directions(basis, max(N_OBSERVATIONS), candidates=args.candidates, eta=eta,
                                        max_theta_deg=float(np.degrees(MAX_THETA)), rng=args.seed + 1,
                                        criterion=criterion)
             for criterion in CRITERIA}
    measure = merl_entry_measure()
    pairs = np.sort(rng.choice(measure.size, args.subset, p=measure / measure.sum()))
    entries = np.sort(rng.choice(np.flatnonzero(measure > 0), args.subset, replace=False))

    results: dict[str, dict] = {}
    for name in materials:
        truth = measured_table(name).reshape(-1)
        score = Scorer(basis, truth, pairs, entries)
        row: dict = {"mean_table": score(np.zeros(basis.n_components)),
                     "best_in_basis": score(project_table(basis, truth)), "n": {}}
        for n in N_OBSERVATIONS:
            draws = {f: [] for f in ETA_FACTORS}
            for _ in range(args.draws):
                wi = uniform_hemisphere_directions(rng, n, MAX_THETA)
                wo = uniform_hemisphere_directions(rng, n, MAX_THETA)
                entries = merl_entries(wi, wo).reshape(-1)
                values = truth[entries] * (1 + args.noise * rng.normal(size=entries.size))
                for factor in ETA_FACTORS:
                    c = fit_coefficients(basis, entries, values, eta=factor * eta)
                    draws[factor].append(score(c))
            row["n"][n] = {f"eta_x{factor:g}": quartiles(ds) for factor, ds in draws.items()}
            # The planned pairs (the same for every material; only the noise is drawn again).
            for criterion, plan in plans.items():
                entries = merl_entries(plan.wi[:n], plan.wo[:n]).reshape(-1)
                planned = [score(fit_coefficients(basis, entries, truth[entries] * (
                    1 + args.noise * planned_rng.normal(size=entries.size)), eta=eta))
                    for _ in range(args.draws if args.noise > 0 else 1)]
                row["n"][n][f"planned_{criterion}"] = quartiles(planned)
        results[name] = row
        print(f"\n{name}: mapped RMSE (median of {args.draws} draws), default eta = {eta:.3g}")
        print(f"  mean table {row['mean_table']['mapped_rmse']:.3f}   best in basis "
              f"{row['best_in_basis']['mapped_rmse']:.3f}   (relative cos-weighted: "
              f"{row['mean_table']['relative_cosine_rmse']:.3f}, {row['best_in_basis']['relative_cosine_rmse']:.3f})")
        print("  n    " + "  ".join(f"eta x{f:<5g}" for f in ETA_FACTORS)
              + "  " + "  ".join(f"{c[:9]:>9}" for c in plans)
              + "  | rel.cos: random " + " ".join(f"{c[:9]:>9}" for c in plans))
        for n, by_eta in row["n"].items():
            cells = "  ".join(f"{by_eta[f'eta_x{f:g}']['mapped_rmse']['median']:9.3f}" for f in ETA_FACTORS)
            planned = "  ".join(f"{by_eta[f'planned_{c}']['mapped_rmse']['median']:9.3f}" for c in plans)
            relative = " ".join(f"{by_eta[f'planned_{c}']['relative_cosine_rmse']['median']:9.3f}" for c in plans)
            print(f"  {n:<4d} {cells}  {planned}  |   {by_eta['eta_x1']['relative_cosine_rmse']['median']:9.3f} "
                  f"{relative}")

    summary = {
        "basis": {"file": str(basis_path), "components": basis.n_components,
                  "training_materials": len(trained), "default_eta": eta,
                  "residual_variance": basis.residual_variance},
        "protocol": {"n_observations": list(N_OBSERVATIONS), "draws": args.draws, "noise": args.noise,
                     "max_theta_deg": float(np.degrees(MAX_THETA)), "scored_entries": args.subset,
                     "eta_factors": list(ETA_FACTORS), "seed": args.seed,
                     "planned": {"candidates": args.candidates,
                                 "expected_rmse": {c: plan.expected_rmse.tolist() for c, plan in plans.items()}}},
        "materials": results,
        "wall_s": time.perf_counter() - start,
        "machine": platform.platform(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=2))
    plot(summary, args.out.with_suffix(".png"))
    print(f"\nwrote {args.out} and {args.out.with_suffix('.png').name} ({summary['wall_s']:.0f} s)")


def plot(summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = (("mapped_rmse", "mapped RMSE (log-relative units)"),
               ("relative_cosine_rmse", "relative cosine-weighted RMSE"))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    n = np.array(summary["protocol"]["n_observations"])
    for (metric, label), ax in zip(metrics, axes[:2]):
        for i, (name, row) in enumerate(summary["materials"].items()):
            colour = f"C{i}"
            stats = [row["n"][str(k) if str(k) in row["n"] else k]["eta_x1"][metric] for k in n]
            ax.plot(n, [s["median"] for s in stats], "o-", color=colour, label=name)
            for criterion, style in (("mapped", "s-."), ("radiance", "^:")):
                planned = [row["n"][str(k) if str(k) in row["n"] else k][f"planned_{criterion}"][metric]["median"]
                           for k in n]
                ax.plot(n, planned, style, color=colour, mfc="none")
            ax.fill_between(n, [s["q25"] for s in stats], [s["q75"] for s in stats], color=colour, alpha=0.2)
            ax.axhline(row["mean_table"][metric], color=colour, ls="--", lw=0.8)
            ax.axhline(row["best_in_basis"][metric], color=colour, ls=":", lw=0.8)
        ax.set(xscale="log", yscale="log", xlabel="observed direction pairs n", ylabel=label)
    axes[0].legend(fontsize=8, title="random: median, IQR; planned: squares mapped,\ntriangles radiance; "
                                     "-- mean table, : best in basis",
                   title_fontsize=7)
    ax = axes[2]
    for j, factor in enumerate(summary["protocol"]["eta_factors"]):
        med = [np.mean([row["n"][str(k) if str(k) in row["n"] else k][f"eta_x{factor:g}"]["mapped_rmse"]["median"]
                        for row in summary["materials"].values()]) for k in n]
        ax.plot(n, med, "o-", color=f"C{j}", label=f"η = {factor:g} × default")
    ax.set(xscale="log", yscale="log", xlabel="observed direction pairs n",
           ylabel="mapped RMSE, mean over materials", title="choice of η")
    ax.legend(fontsize=8)
    basis = summary["basis"]
    fig.suptitle(f"Held-out BRDF reconstruction: {basis['components']} components, "
                 f"{basis['training_materials']} training materials, noise {summary['protocol']['noise']:g}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
