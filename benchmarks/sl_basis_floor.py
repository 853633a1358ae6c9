"""The basis' own floor against its number of components (docs/sl-study.md).

Each study material's true table projected onto the first K components of one basis of the other
91 materials (every entry observed, η = 0, :func:`abs.brdf.reconstruct.project_table`) and scored
as the study scores (sphere under ``royal_esplanade_1k``, 128x128 at 64 spp, CIEDE2000). PCA
components are nested, so the first K components of a 64-component basis are the K-component basis
of the same materials. What remains at large K is what the neural MERL fits of the other materials
cannot express, whatever the sampling.

    abs brdf build-basis --components 64 --out basis64.npz
    PYTHONPATH=$PWD python3 benchmarks/sl_basis_floor.py --basis basis64.npz \
        --out benchmarks/results/sl_basis_floor.json

Needs ../shared/data (the measured materials and the environment map).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path


def truncated(basis, k: int):
    """The basis of the first ``k`` components (and their training coefficients)."""
    return replace(basis, components=basis.components[:k],
                   training_coefficients=None if basis.training_coefficients is None
                   else basis.training_coefficients[:, :k],
                   singular_values=None if basis.singular_values is None else basis.singular_values[:k],
                   residual_variance=None)


def main() -> None:
    from abs.brdf.basis import BRDFBasis
    from abs.brdf.measured import STUDY_MATERIALS, measured_table
    from abs.brdf.reconstruct import project_table
    from abs.studies.sl_scoring import Scorer, ScoreSettings

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--basis", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--components", default="8,16,32,64")
    parser.add_argument("--score-size", type=int, default=128)
    parser.add_argument("--score-spp", type=int, default=64)
    args = parser.parse_args()
    basis = BRDFBasis.load(args.basis)
    counts = [int(k) for k in args.components.split(",")]
    results: dict = {"settings": {"basis_components": basis.n_components, "components": counts,
                                  "score_size": args.score_size, "score_spp": args.score_spp},
                     "materials": {}}
    start = time.perf_counter()
    for material in STUDY_MATERIALS:
        truth = measured_table(material)
        scorer = Scorer.from_shared(truth, ScoreSettings(args.score_size, args.score_spp))
        row = {}
        for k in counts:
            part = truncated(basis, k)
            score = scorer.score(part.table(project_table(part, truth)))
            row[str(k)] = {"mean": score["mean"], "sd": score["sd"]}
        results["materials"][material] = row
        print(material, {k: round(v["mean"], 3) for k, v in row.items()}, flush=True)
        results["runtime_s"] = time.perf_counter() - start
        args.out.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    import abs.render  # noqa: F401  (selects the Mitsuba variant)

    main()
