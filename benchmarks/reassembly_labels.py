"""Reassembly, micropolygon labelling on photographs rendered by abs (issue 26): a floor and a
back wall with four regions of known diffuse materials (red strip, green, blue disc, grey wall;
``abs.reassembly.label_truth``), lit by the default scene's environment map and rendered by abs's
path tracer (Mitsuba) from three calibrated cameras. Each photograph is segmented (edges +
watershed), the regions labelled across the photographs (k-means, five labels: the four regions
and the dark surroundings), the scanned background (a coarse mesh of the same floor and wall,
3x3 squares on the floor) subdivided to the pixel footprint and labelled.

Reported per image size and samples per pixel: the area-weighted share of faces labelled right
(labels matched one-to-one to the regions, Hungarian assignment on the area confusion matrix),
the same per region, the faces after subdivision, the share labelled by nearest neighbour, the
render and labelling times. Writes ``benchmarks/results/reassembly_labels.json`` and ``.md``.

    PYTHONPATH=. python benchmarks/reassembly_labels.py [--width 96 160 320] [--spp 8 32]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from abs.reassembly.label_truth import REGIONS, region_of, scanned_background, truth_cameras, truth_scene
from abs.reassembly.labelling import LabelCamera, label_mesh
from abs.reassembly.segmentation import label_regions, segment_photograph

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "reassembly_labels.json"
N_LABELS = len(REGIONS) + 1


def run(width: int, spp: int) -> dict:
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene

    height = width * 3 // 4
    cams = truth_cameras(width, height)
    with tempfile.TemporaryDirectory() as tmp:
        compiled = compile_scene(load_scene(truth_scene(tmp, spp)))
        start = time.perf_counter()
        images = [compiled.render(Camera(K, R, t, width, height), spp=spp, seed=i).numpy()
                  for i, (K, R, t) in enumerate(cams)]
        render_s = time.perf_counter() - start
    start = time.perf_counter()
    segs = [segment_photograph(im) for im in images]
    label_images, _ = label_regions(segs, N_LABELS)
    cameras = [LabelCamera(f"cam{i}", K, R, t, lab) for i, ((K, R, t), lab) in enumerate(zip(cams, label_images))]
    result = label_mesh(scanned_background(), cameras, N_LABELS)
    label_s = time.perf_counter() - start
    mesh, labels = result.mesh, result.face_labels
    truth = region_of(mesh.triangles_center)
    area = mesh.area_faces
    conf = np.zeros((N_LABELS + 1, len(REGIONS) + 1))
    np.add.at(conf, (labels, truth), area)
    rows, cols = linear_sum_assignment(-conf)
    right = np.zeros(len(REGIONS) + 1)
    right[cols] = conf[rows, cols]
    per_region = {name: float(right[k] / conf[:, k].sum()) for k, (name, _) in enumerate(REGIONS, start=1)}
    return {"width": width, "height": height, "spp": spp, "regions_per_view": [len(s.areas) for s in segs],
            "faces": int(len(labels)), "subdivision_rounds": result.rounds,
            "nearest_neighbour_share": float(area[~result.voted].sum() / area.sum()),
            "accuracy_area": float(right.sum() / area.sum()), "accuracy_per_region": per_region,
            "render_s": render_s, "label_s": label_s}


def markdown(rows: list[dict], commit: str) -> str:
    lines = ["# Reassembly: micropolygon labelling on photographs rendered by abs", "",
             f"Floor and wall with four regions of known materials, three cameras, five labels; commit {commit}.", "",
             "| size, spp | faces (rounds) | by nearest neighbour | labelled right (area) | "
             + " | ".join(n for n, _ in REGIONS) + " | render / label time |",
             "|---|---|---|---|" + "---|" * len(REGIONS) + "---|"]
    for r in rows:
        lines.append(f"| {r['width']}x{r['height']}, {r['spp']} | {r['faces']} ({r['subdivision_rounds']}) | "
                     f"{100 * r['nearest_neighbour_share']:.2f} % | {100 * r['accuracy_area']:.2f} % | "
                     + " | ".join(f"{100 * r['accuracy_per_region'][n]:.1f} %" for n, _ in REGIONS)
                     + f" | {r['render_s']:.1f} / {r['label_s']:.1f} s |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--width", type=int, nargs="+", default=[96, 160, 320])
    parser.add_argument("--spp", type=int, nargs="+", default=[8, 32])
    parser.add_argument("--results", type=Path, default=RESULTS, help="JSON to write (and .md beside it)")
    args = parser.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    rows = []
    for width in args.width:
        for spp in args.spp:
            row = run(width, spp)
            print(json.dumps(row))
            rows.append(row)
    args.results.parent.mkdir(parents=True, exist_ok=True)
    args.results.write_text(json.dumps({"machine": platform.platform(), "commit": commit, "rows": rows},
                                       indent=1) + "\n")
    args.results.with_suffix(".md").write_text(markdown(rows, commit))
    print(markdown(rows, commit))


if __name__ == "__main__":
    main()
