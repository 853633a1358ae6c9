"""Two likely causes of abs's difference from the paper's published Table 1, measured (docs/sl-study.md).

For each study material on the error-free icosphere 5 at the study's full size (640x480 scanner
images, 4 spp; score 128x128 at 64 spp), as `abs study sl-scanner` does:

- **lights**: the reconstruction from the scene light alone (abs's study), from the projector alone
  (the paper's row 5*) and from both (the paper's rows 1, 3, 5), scored under the study's default
  environment map. The projector lights from between the cameras, so it adds near-backscatter
  observations the scene light never makes.
- **environment**: the scene-light reconstruction scored under each of the four Poly Haven maps and
  two Blender studio-light worlds: how far the score moves with a map the paper did not name.
- **basis**: the basis' own floor (the truth projected onto the basis, every entry, η = 0) and the
  scene-light reconstruction with η ten times smaller and larger than the default: how much of
  the error is the basis (neural MERL fits, 32 components) rather than the sampling.

The scene-light, royal_esplanade number equals the study's Table 1 cell (same seeds): a check
that this script measures what the study measures.

    PYTHONPATH=$PWD python3 benchmarks/sl_paper_causes.py --basis basis.npz \
        --out benchmarks/results/sl_paper_causes.json

Needs ../shared/data (the measured materials and the environment maps).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ENVIRONMENTS = (
    "polyhaven_hdri_1k/royal_esplanade_1k.hdr",
    "polyhaven_hdri_1k/venice_sunset_1k.hdr",
    "polyhaven_hdri_1k/pedestrian_overpass_1k.hdr",
    "polyhaven_hdri_1k/moonless_golf_1k.hdr",
    "blender_studiolights_world_cc0/studio.exr",
    "blender_studiolights_world_cc0/interior.exr",
)


def _concatenate(a, b):
    from abs.studies.sl_sampling import BRDFSamples

    return BRDFSamples(np.concatenate([a.wi, b.wi]), np.concatenate([a.wo, b.wo]),
                       np.concatenate([a.f, b.f]), a.candidates + b.candidates)


def measure(material: str, basis, width: int, height: int, spp: int, score_size: int, score_spp: int,
            tessellation: int, environments: tuple[str, ...], seed: int = 0) -> dict:
    """Scores (CIEDE2000 mean, sd over the sphere's pixels) of one material; see the module docstring."""
    from abs.brdf.directions import merl_entries
    from abs.brdf.measured import measured_table
    from abs.brdf.reconstruct import default_eta, project_table, reconstruct
    from abs.studies.sl_capture import render_scan
    from abs.studies.sl_noise import ScanEstimate
    from abs.studies.sl_rig import default_rig, icosphere
    from abs.studies.sl_sampling import brdf_samples
    from abs.studies.sl_scoring import Scorer, ScoreSettings

    truth = measured_table(material)
    rig, mesh = default_rig(width, height), icosphere(tessellation)
    projector_rig = replace(rig, light_position=rig.projector_position)
    samples = {}
    for name, lit in (("scene_light", rig), ("projector", projector_rig)):
        images = render_scan(lit, mesh, truth, spp=spp, seed=seed)
        samples[name] = brdf_samples(images, lit, ScanEstimate(mesh, lit.light_position, lit.light_intensity))
    samples["both"] = _concatenate(samples["scene_light"], samples["projector"])
    tables = {name: reconstruct(basis, merl_entries(s.wi, s.wo), s.f) for name, s in samples.items()}
    scene = samples["scene_light"]
    eta = default_eta(basis)
    variants = {"projection": basis.table(project_table(basis, truth))}
    for factor in (0.1, 10.0):
        variants[f"eta_x{factor:g}"] = reconstruct(basis, merl_entries(scene.wi, scene.wo), scene.f, eta=factor * eta)
    out: dict = {"samples": {k: s.count for k, s in samples.items()}, "eta": eta, "lights": {},
                 "environment": {}, "basis": {}}
    for environment in environments:
        scorer = Scorer.from_shared(truth, ScoreSettings(score_size, score_spp, seed, environment))
        if environment == environments[0]:
            for name, table in variants.items():
                score = scorer.score(table)
                out["basis"][name] = {"mean": score["mean"], "sd": score["sd"]}
        names = tables if environment == environments[0] else ("scene_light",)
        for name in names:
            score = scorer.score(tables[name])
            cell = {"mean": score["mean"], "sd": score["sd"]}
            if environment == environments[0]:
                out["lights"][name] = cell
            if name == "scene_light":
                out["environment"][environment] = cell
    return out


def main() -> None:
    from abs.brdf.basis import BRDFBasis
    from abs.brdf.measured import STUDY_MATERIALS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--basis", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--materials", default=",".join(STUDY_MATERIALS))
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--score-size", type=int, default=128)
    parser.add_argument("--score-spp", type=int, default=64)
    parser.add_argument("--tessellation", type=int, default=5)
    args = parser.parse_args()
    basis = BRDFBasis.load(args.basis)
    settings = {k: getattr(args, k) for k in ("width", "height", "spp", "score_size", "score_spp", "tessellation")}
    results = {"settings": {**settings, "environments": list(ENVIRONMENTS)}, "materials": {}}
    start = time.perf_counter()
    for material in args.materials.split(","):
        t0 = time.perf_counter()
        results["materials"][material] = measure(material, basis, environments=ENVIRONMENTS, **settings)
        print(material, f"{time.perf_counter() - t0:.0f} s", json.dumps(results["materials"][material]), flush=True)
        results["runtime_s"] = time.perf_counter() - start
        args.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    import abs.render  # noqa: F401  (selects the Mitsuba variant)

    main()
