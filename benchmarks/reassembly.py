"""Reassembly (issue 26, first part): CT meshing and marker placement on a synthetic CT volume
whose truth is known.

The phantom (abs/reassembly/phantom.py) is the default scene's glass sphere (radius 40 mm) or
its thin-walled bowl (``scenes/default/bowl.ply``: 120 mm across, 3 mm walls) with 7 markers
(radius 1.5 mm, centres 0.75 mm outside the glass surface) at random places, grey values air 200,
glass +1000, markers +4000, Gaussian noise (sd 40) and streaks along x around each marker (peak
2500), at each voxel size of ``--voxels`` (sphere) and ``--bowl-voxels`` (bowl).

Per voxel size:

- ``meshing``: phantom and meshing times per stage; marker centre and radius errors against the
  truth (mm); the glass mesh's deviation from the true sphere (mean, 95th percentile and max of
  the distance of 50 000 area-uniform surface samples, mm) for the raw iso-surface, the cleaned
  mesh before the √3 loop (carved, holes filled, decimated to 1 %, not below 2000 faces) and after
  4 rounds of √3 subdivision + decimation to a third; and the cleaned mesh carved with
  epsilon = 0.75 instead of the default 0.5.
- ``placement``: the CT marker centres found by the meshing are placed onto the *true* marker
  centres moved by a random rigid transform (rotation uniform, the object centre at the scene
  sphere's (0, 0.04, 0) m) plus Gaussian noise of sd ``sigma`` per axis, standing in for stereo
  triangulation (measured on renderings by benchmarks/reassembly_stereo.py), one marker dropped
  in half the trials. Automatic pairing, Kabsch;
  mean marker distance (mm; the seed reached 0.43 mm on its teapot), rotation error (deg), error
  of the translation of ``to_world`` and of the object centre's placement (mm), 20 trials per
  sigma. The mean marker distance is dominated by the assumed sigma: it checks that the pairing
  and the CT centres add little, not that stereo reaches 0.43 mm.

Writes ``benchmarks/results/reassembly.json`` and ``.md``.

    PYTHONPATH=. python benchmarks/reassembly.py [--voxels 0.8,0.5,0.3,0.2] [--bowl-voxels 0.8,0.5,0.3]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from abs.reassembly.cleaning import (carve_spheres, decimate, fill_holes, largest_component,
                                     subdivide_decimate)
from abs.reassembly.meshing import MeshingSettings, mesh_volume
from abs.reassembly.phantom import make_phantom
from abs.reassembly.placement import place

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "reassembly.json"
GLASS_RADIUS_MM = 40.0
MARKERS = 7
MARKER_RADIUS_MM = 1.5
SIGMAS_MM = (0.0, 0.1, 0.2, 0.3)
TRIALS = 20
SEED_TARGET_MM = 0.43


def deviation(phantom, mesh: trimesh.Trimesh, n: int = 50_000) -> dict:
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=0)
    d = phantom.glass_distance_mm(pts)
    return {"mean_mm": float(d.mean()), "p95_mm": float(np.percentile(d, 95)), "max_mm": float(d.max()),
            "faces": int(len(mesh.faces)), "watertight": bool(mesh.is_watertight)}


def run_voxel(voxel: float, glass: str = "sphere") -> dict:
    t0 = time.perf_counter()
    mesh = None
    if glass == "bowl":
        mesh = trimesh.load(ROOT / "scenes" / "default" / "bowl.ply", force="mesh", process=False)
        mesh.apply_scale(1000.0)  # m -> mm
    phantom = make_phantom(voxel, glass_radius_mm=GLASS_RADIUS_MM, n_markers=MARKERS,
                           marker_radius_mm=MARKER_RADIUS_MM, seed=0, glass_mesh_mm=mesh)
    t_phantom = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = mesh_volume(phantom.volume, MeshingSettings(rounds=0))
    t_mesh = time.perf_counter() - t0
    t0 = time.perf_counter()
    looped = subdivide_decimate(result.glass, 4)
    t_loop = time.perf_counter() - t0
    seconds = dict(result.seconds, subdivide_decimate=t_loop)
    settings = MeshingSettings()
    carved = fill_holes(largest_component(carve_spheres(result.glass_raw, result.centres_mm,
                                                        result.radii_mm, 0.75)))
    carved = decimate(carved, faces=max(settings.min_faces, int(round(settings.keep * len(carved.faces)))))

    found = result.centres_mm
    d = np.linalg.norm(found[:, None] - phantom.marker_centres_mm[None], axis=2)
    idx = d.argmin(axis=1)
    centre_err = d[np.arange(len(found)), idx]
    radius_err = result.radii_mm - phantom.marker_radii_mm[idx]
    out = {
        "glass": glass,
        "voxel_mm": voxel,
        "shape": list(phantom.volume.data.shape),
        "phantom_seconds": t_phantom,
        "meshing_seconds": t_mesh + t_loop,
        "stage_seconds": seconds,
        "markers_true": MARKERS,
        "markers_found": len(found),
        "markers_distinct": len(set(idx.tolist())),
        "marker_centre_error_mm": {"mean": float(centre_err.mean()), "max": float(centre_err.max())},
        "marker_radius_error_mm": {"mean": float(radius_err.mean()), "max_abs": float(np.abs(radius_err).max())},
        "glass_deviation": {"iso_surface": deviation(phantom, result.glass_raw),
                            "cleaned": deviation(phantom, result.glass),
                            "cleaned_sqrt3_loop": deviation(phantom, looped),
                            "cleaned_epsilon_0.75": deviation(phantom, carved)},
        "placement": placement(phantom, found),
    }
    return out


def placement(phantom, found_mm: np.ndarray) -> list[dict]:
    ct = found_mm * 1e-3
    truth = phantom.marker_centres_mm * 1e-3
    centre = phantom.glass_centre_mm * 1e-3  # the sphere's centre, the bowl's bounding-box centre
    rows = []
    for sigma in SIGMAS_MM:
        rng = np.random.default_rng(int(sigma * 1000) + 1)
        stats = {"mean_marker_distance_mm": [], "rotation_error_deg": [], "translation_error_mm": [],
                 "object_centre_error_mm": [], "pairing_correct": [], "errors": []}
        for trial in range(TRIALS):
            R = Rotation.random(random_state=rng).as_matrix()
            t = np.array([0.0, 0.04, 0.0]) - R @ centre
            measured = truth @ R.T + t + rng.normal(0, sigma * 1e-3, truth.shape)
            order = rng.permutation(len(truth))
            if trial % 2:
                order = order[:-1]
            try:
                res = place(measured[order], ct)
            except Exception as exc:  # noqa: BLE001 - counted, reported
                stats["errors"].append(str(exc))
                continue
            # found marker j is the true marker nearest it; the pair is right if measured order[i] is it
            d = np.linalg.norm(ct[:, None] - truth[None], axis=2).argmin(axis=1)
            stats["pairing_correct"].append(bool(np.all(order[res.pairs[:, 0]] == d[res.pairs[:, 1]])))
            stats["mean_marker_distance_mm"].append(res.mean_distance_mm)
            stats["rotation_error_deg"].append(float(np.degrees(Rotation.from_matrix(res.R @ R.T).magnitude())))
            stats["translation_error_mm"].append(float(np.linalg.norm(res.t - t) * 1e3))
            stats["object_centre_error_mm"].append(float(np.linalg.norm(res.R @ centre + res.t - (R @ centre + t)) * 1e3))
        row = {"sigma_mm": sigma, "trials": TRIALS, "failures": len(stats["errors"]),
               "pairing_correct": int(sum(stats["pairing_correct"])), "first_error": stats["errors"][:1]}
        for key in ("mean_marker_distance_mm", "rotation_error_deg", "translation_error_mm", "object_centre_error_mm"):
            v = np.asarray(stats[key])
            row[key] = {"mean": float(v.mean()) if v.size else None, "max": float(v.max()) if v.size else None}
        rows.append(row)
    return rows


def markdown(data: dict) -> str:
    lines = ["# Reassembly benchmark (issue 26, first part)", "",
             f"Synthetic CT: glass sphere r = {GLASS_RADIUS_MM:g} mm or the bowl of scenes/default (3 mm walls), "
             f"{MARKERS} markers r = {MARKER_RADIUS_MM:g} mm, "
             "noise and streaks (see benchmarks/reassembly.py). "
             f"Machine: {data['machine']}; {data['date']}.", "",
             "## Meshing", "",
             "Glass deviation: distance of 50 000 area samples of the mesh from the true surface, mm. "
             "The iso-surface still holds the markers and the streaks.", "",
             "| glass | voxel mm | shape | phantom s | meshing s | markers found | centre err mean / max mm | radius err max mm "
             "| iso-surface dev mean / p95 mm | cleaned dev mean / p95 / max mm | after √3 loop mean / p95 / max mm "
             "| epsilon 0.75: mean / p95 / max mm | faces (cleaned / after loop) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in data["runs"]:
        g = r["glass_deviation"]
        lines.append(
            f"| {r['glass']} | {r['voxel_mm']:g} | {'x'.join(map(str, r['shape']))} | {r['phantom_seconds']:.1f} | {r['meshing_seconds']:.1f} "
            f"| {r['markers_found']}/{r['markers_true']} | {r['marker_centre_error_mm']['mean']:.3f} / {r['marker_centre_error_mm']['max']:.3f} "
            f"| {r['marker_radius_error_mm']['max_abs']:.3f} "
            f"| {g['iso_surface']['mean_mm']:.3f} / {g['iso_surface']['p95_mm']:.3f} "
            f"| {g['cleaned']['mean_mm']:.3f} / {g['cleaned']['p95_mm']:.3f} / {g['cleaned']['max_mm']:.2f} "
            f"| {g['cleaned_sqrt3_loop']['mean_mm']:.3f} / {g['cleaned_sqrt3_loop']['p95_mm']:.3f} / {g['cleaned_sqrt3_loop']['max_mm']:.2f} "
            f"| {g['cleaned_epsilon_0.75']['mean_mm']:.3f} / {g['cleaned_epsilon_0.75']['p95_mm']:.3f} / {g['cleaned_epsilon_0.75']['max_mm']:.2f} "
            f"| {g['cleaned']['faces']} / {g['cleaned_sqrt3_loop']['faces']} |")
    open_meshes = [f"{r['glass']} {r['voxel_mm']:g} mm {k}" for r in data["runs"]
                   for k, g in r["glass_deviation"].items() if not g["watertight"]]
    lines += ["", "Closed (watertight) meshes: " + ("all" if not open_meshes else "all but " + ", ".join(open_meshes)) + "."]
    lines += ["", "Stage times (s):", ""]
    for r in data["runs"]:
        lines.append(f"- {r['glass']}, {r['voxel_mm']:g} mm: " + ", ".join(f"{k} {v:.2f}" for k, v in r["stage_seconds"].items()))
    lines += ["", "## Placement", "",
              f"CT centres from the meshing placed onto the true markers under a random rigid transform plus "
              f"triangulation noise sigma per axis; {TRIALS} trials per row, one marker dropped in half. "
              f"Target: mean marker distance <= {SEED_TARGET_MM} mm (the seed's figure).", "",
              "| glass | voxel mm | sigma mm | pairing right | mean marker distance mean / max mm | rotation err mean / max deg "
              "| to_world translation err mean / max mm | object-centre err mean / max mm |",
              "|---|---|---|---|---|---|---|---|"]
    for r in data["runs"]:
        for p in r["placement"]:
            f = lambda k, d=3: f"{p[k]['mean']:.{d}f} / {p[k]['max']:.{d}f}" if p[k]["mean"] is not None else "-"
            lines.append(f"| {r['glass']} | {r['voxel_mm']:g} | {p['sigma_mm']:g} | {p['pairing_correct']}/{p['trials']} "
                         f"| {f('mean_marker_distance_mm')} | {f('rotation_error_deg')} | {f('translation_error_mm')} "
                         f"| {f('object_centre_error_mm')} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxels", default="0.8,0.5,0.3,0.2", help="voxel sizes of the sphere, mm")
    ap.add_argument("--bowl-voxels", default="0.8,0.5,0.3", help="voxel sizes of the bowl, mm ('' for none)")
    args = ap.parse_args()
    runs = []
    jobs = [("sphere", float(x)) for x in args.voxels.split(",") if x] + \
        [("bowl", float(x)) for x in args.bowl_voxels.split(",") if x]
    for glass, v in jobs:
        print(f"{glass}, voxel {v} mm ...", flush=True)
        runs.append(run_voxel(v, glass))
        r = runs[-1]
        print(f"  meshing {r['meshing_seconds']:.1f} s, centre err max {r['marker_centre_error_mm']['max']:.3f} mm, "
              f"dev {r['glass_deviation']['cleaned']['mean_mm']:.3f} mm", flush=True)
    data = {"machine": f"{platform.processor() or platform.machine()}, {platform.system()}",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "glass_radius_mm": GLASS_RADIUS_MM, "markers": MARKERS, "marker_radius_mm": MARKER_RADIUS_MM,
            "seed_target_mm": SEED_TARGET_MM, "runs": runs}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    RESULTS.with_suffix(".md").write_text(markdown(data), encoding="utf-8")
    print(markdown(data))


if __name__ == "__main__":
    main()
