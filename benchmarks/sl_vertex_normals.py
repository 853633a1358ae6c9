"""Vertex-position noise with the normals kept (abs's error model) or recomputed from the noisy mesh.

The paper's Table 2 says vertex positions got Gaussian noise on x, y, z but not whether the
normals used for the BRDF samples followed the moved vertices. abs keeps the true normals
(`abs/studies/sl_noise.py`). This script measures, on the error-free icosphere 5 scan at the study's
full size, the CIEDE2000 score of both readings with the *same* noise draws (paired), to see which
one the paper's numbers resemble (docs/sl-study.md).

    PYTHONPATH=$PWD python3 benchmarks/sl_vertex_normals.py --basis basis.npz \
        --out benchmarks/results/sl_vertex_normals.json

Needs ../shared/data (the measured materials and the environment map).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def recomputed_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals of a triangle mesh: the area-weighted mean of its faces' normals
    (trimesh's ``vertex_normals``), (N, 3)."""
    import trimesh

    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    return np.asarray(mesh.vertex_normals, np.float64)


def measure(material: str, basis, levels_mm: tuple[float, ...], repetitions: int, width: int, height: int,
            spp: int, score_size: int, score_spp: int, tessellation: int, seed: int = 0) -> dict:
    """{"kept"|"recomputed": {level: {"mean", "sd", "means", "samples"}}} over repetitions."""
    from abs.brdf.directions import merl_entries
    from abs.brdf.measured import measured_table
    from abs.brdf.reconstruct import reconstruct
    from abs.studies.sl_capture import render_scan
    from abs.studies.sl_noise import ScanEstimate, perturb
    from abs.studies.sl_rig import SampleMesh, default_rig, icosphere
    from abs.studies.sl_sampling import brdf_samples
    from abs.studies.sl_scoring import Scorer, ScoreSettings

    truth = measured_table(material)
    rig, mesh = default_rig(width, height), icosphere(tessellation)
    images = render_scan(rig, mesh, truth, spp=spp, seed=seed)
    scorer = Scorer.from_shared(truth, ScoreSettings(score_size, score_spp, seed))
    exact = ScanEstimate(mesh, rig.light_position, rig.light_intensity)
    out: dict = {"kept": {}, "recomputed": {}}
    for level in levels_mm:
        scores: dict = {"kept": [], "recomputed": []}
        counts: dict = {"kept": [], "recomputed": []}
        for repetition in range(repetitions):
            moved = perturb(exact, "vertex_position", level, np.random.default_rng([seed, int(level * 10), repetition]))
            normals = recomputed_normals(moved.mesh.vertices, moved.mesh.faces)
            estimates = {"kept": moved,
                         "recomputed": replace(moved, mesh=SampleMesh(moved.mesh.vertices, moved.mesh.faces, normals))}
            for name, estimate in estimates.items():
                samples = brdf_samples(images, rig, estimate)
                counts[name].append(samples.count)
                if samples.count == 0:
                    continue
                table = reconstruct(basis, merl_entries(samples.wi, samples.wo), samples.f)
                scores[name].append(scorer.score(table)["mean"])
        for name in scores:
            means = np.asarray(scores[name])
            out[name][f"{level:g}"] = {
                "mean": float(means.mean()) if means.size else None,
                "sd": float(means.std(ddof=1)) if means.size > 1 else None,
                "means": means.tolist(), "samples": counts[name]}
    return out


def main() -> None:
    from abs.brdf.basis import BRDFBasis
    from abs.brdf.measured import STUDY_MATERIALS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--basis", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--materials", default=",".join(STUDY_MATERIALS))
    parser.add_argument("--levels", default="1,3,5", help="vertex σ per axis, mm")
    parser.add_argument("--repetitions", type=int, default=5)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--score-size", type=int, default=128)
    parser.add_argument("--score-spp", type=int, default=64)
    parser.add_argument("--tessellation", type=int, default=5)
    args = parser.parse_args()
    basis = BRDFBasis.load(args.basis)
    levels = tuple(float(x) for x in args.levels.split(","))
    settings = {k: getattr(args, k) for k in ("repetitions", "width", "height", "spp", "score_size",
                                               "score_spp", "tessellation")}
    results = {"settings": {**settings, "levels_mm": list(levels)}, "materials": {}}
    start = time.perf_counter()
    for material in args.materials.split(","):
        t0 = time.perf_counter()
        results["materials"][material] = measure(material, basis, levels, **settings)
        row = {n: {k: round(v["mean"], 3) for k, v in r.items() if v["mean"] is not None}
               for n, r in results["materials"][material].items()}
        print(material, f"{time.perf_counter() - t0:.0f} s", row, flush=True)
        results["runtime_s"] = time.perf_counter() - start
        args.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    import abs.render  # noqa: F401  (selects the Mitsuba variant)

    main()
