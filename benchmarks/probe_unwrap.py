"""Mirror-ball unwrapping on Mitsuba renderings of a chrome ball under a real HDR map.

A chromium ball (Mitsuba's analytic ``sphere`` with a smooth ``conductor`` BSDF, eta and k per
channel from Johnson & Christy's data integrated by ``abs glass rgb``) lit by a Poly Haven map
(``../shared/data/polyhaven_hdri_1k/``, area-downsampled to the output map's size), photographed
by calibrated pinhole cameras at a finite distance (10 ball radii). The photographs are saved
as a capture folder and unwrapped by ``abs probe unwrap`` (CLI) and by the Python API with every
model variant; each result is compared with the true map over the directions it recovers:

- relative MAE: ``mean |rec - true| / mean true`` over texels with view weight > 0.3 (away from
  the outline, where one pixel spans many directions), and over every seen texel, the pole rows
  left out (each is a single direction);
- the same away from the brightest 1 % of the true map's texels (dilated by 3 texels: the sun
  and the texels its image spreads into, which dominate every absolute error);
- median and 90th percentile of the per-texel relative error ``|rec - true| / true``.

A sweep over the camera distance (3 to 50 radii, one view) shows where the pinhole model matters.

Then a scene (a diffuse and a rough-metal sphere, Mitsuba) is rendered lit by the true map and
by the two-view recovered map, and the image RMSE is reported relative to the true image's mean.

Writes ``benchmarks/results/probe_unwrap.json``.

    python benchmarks/probe_unwrap.py [--map royal_esplanade_1k.hdr --size 256 --spp 128]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at
from abs.colour import optical_constants_rgb, read_refractiveindex_yaml
from abs.io.capture import save_capture
from abs.io.images import read_image
from abs.io.shared_data import shared_data_dir
from abs.probe import ProbeView, latlong_directions, merge_views, unwrap_view

ROOT = Path(__file__).resolve().parents[1]
CENTER, RADIUS, DISTANCE = np.array([0.0, 0.0, 0.0]), 0.05, 0.5
EYES = {"front": [0.0, 0.0, DISTANCE], "back": [0.0, 0.05, -DISTANCE]}


def _sensor(mi, K, R, t, size):
    eye = -R.T @ t
    fov = np.degrees(2.0 * np.arctan(size / 2.0 / K[1, 1]))
    to_world = mi.ScalarTransform4f().look_at(origin=eye.tolist(), target=(eye + R[2]).tolist(),
                                              up=(-R[1]).tolist())
    return {"type": "perspective", "fov": float(fov), "fov_axis": "y", "to_world": to_world,
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"}}


def _render(mi, envmap, shapes, sensor, spp):
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 4},
                          "emitter": {"type": "envmap", "bitmap": mi.Bitmap(envmap.astype(np.float32))},
                          "sensor": sensor, **shapes})
    return np.asarray(mi.render(scene, spp=spp, seed=1), np.float64)


def _errors(rec, weight, truth) -> dict:
    out = {}
    lum = truth.mean(-1)
    # The sun's few texels, and their neighbours into which a photograph's pixel footprint
    # spreads it, dominate every absolute error: a second figure leaves out the brightest 1 %
    # of the true map's texels dilated by 3 texels.
    bright = (lum > np.percentile(lum, 99)).astype(np.uint8)
    dim = cv2.dilate(bright, np.ones((7, 7), np.uint8)) == 0
    # The first and last rows are the poles (Mitsuba puts row centres at theta = pi j/(H-1)):
    # each is one direction, so their texels cannot differ in a recovered map; left out.
    inner = np.zeros(lum.shape, bool)
    inner[1:-1] = True
    for label, sel in (("weight>0.3", (weight > 0.3) & inner), ("seen", (weight > 0) & inner)):
        diff = np.abs(rec - truth)[sel]
        both = sel & dim
        out[label] = {"fraction_of_texels": float(sel.mean()),
                      "relative_mae": float(diff.mean() / truth[sel].mean()),
                      "relative_mae_away_from_brightest_1pct": float(
                          np.abs(rec - truth)[both].mean() / truth[both].mean()),
                      "median_relative": float(np.median(diff / np.maximum(truth[sel], 1e-6))),
                      "p90_relative": float(np.percentile(diff / np.maximum(truth[sel], 1e-6), 90))}
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--map", default="royal_esplanade_1k.hdr")
    p.add_argument("--size", type=int, default=256, help="photograph width = height, pixels")
    p.add_argument("--map-width", type=int, default=128, help="environment map width (height = width/2)")
    p.add_argument("--spp", type=int, default=128)
    args = p.parse_args()

    data = shared_data_dir()
    map_path = data / "polyhaven_hdri_1k" / args.map
    chrome_path = data / "refractiveindex_info/data/main/Cr/nk/Johnson.yml"
    if not map_path.is_file() or not chrome_path.is_file():
        raise SystemExit(f"shared data absent: {map_path} or {chrome_path} (see ../shared/README.md)")
    from abs.render.variant import set_variant

    set_variant(None)
    import mitsuba as mi

    mw, mh = args.map_width, args.map_width // 2
    truth = cv2.resize(read_image(map_path), (mw, mh), interpolation=cv2.INTER_AREA).astype(np.float64)
    chrome = optical_constants_rgb(read_refractiveindex_yaml(chrome_path))
    eta, k = chrome["ior_rgb"], chrome["k_rgb"]
    ball = {"ball": {"type": "sphere", "center": CENTER.tolist(), "radius": RADIUS,
                     "bsdf": {"type": "conductor", "eta": {"type": "rgb", "value": eta},
                              "k": {"type": "rgb", "value": k}}}}
    # The ball's outline fills about 80 % of the image height.
    K = intrinsics_from_fov(args.size, args.size, 2.5 * np.arcsin(RADIUS / DISTANCE))
    start = time.perf_counter()
    views, images = [], {}
    for name, eye in EYES.items():
        R, t = look_at(eye, CENTER)
        images[name] = _render(mi, truth, ball, _sensor(mi, K, R, t, args.size), args.spp)
        views.append({"name": name, "K": K, "R": R, "t": t})
    render_s = time.perf_counter() - start
    dirs = latlong_directions(mw, mh)
    probes = {v["name"]: ProbeView(v["name"], images[v["name"]], K, v["R"], v["t"]) for v in views}
    variants = {"pinhole+fresnel": dict(model="pinhole", eta_rgb=eta, k_rgb=k),
                "pinhole": dict(model="pinhole"),
                "pinhole-closed-formula+fresnel": dict(model="pinhole", iterations=0, eta_rgb=eta, k_rgb=k),
                "orthographic+fresnel": dict(model="orthographic", eta_rgb=eta, k_rgb=k),
                "orthographic": dict(model="orthographic")}
    results = {"map": args.map, "map_size": [mw, mh], "photo_size": args.size, "spp": args.spp,
               "ball_radius_m": RADIUS, "camera_distance_m": DISTANCE, "chromium_eta_rgb": eta,
               "chromium_k_rgb": k, "render_seconds": round(render_s, 1),
               "single_view_front": {}, "two_views_merged": {}}
    merged_maps = {}
    for label, kw in variants.items():
        one = unwrap_view(probes["front"], CENTER, RADIUS, dirs, **kw)
        results["single_view_front"][label] = _errors(one[0], one[1], truth)
        both = merge_views([one, unwrap_view(probes["back"], CENTER, RADIUS, dirs, **kw)])
        results["two_views_merged"][label] = _errors(both[0], both[1], truth)
        merged_maps[label] = both
        print(f"{label:32s} front: rel. MAE {results['single_view_front'][label]['weight>0.3']['relative_mae']:.4f}"
              f"   merged: {results['two_views_merged'][label]['weight>0.3']['relative_mae']:.4f}", flush=True)

    # How much the pinhole model matters: one front view at several distances (the image keeps
    # the ball's outline at 80 % of its height), pinhole vs orthographic, both Fresnel-divided.
    results["distance_sweep"] = {}
    for radii in (3, 5, 10, 20, 50):
        dist = radii * RADIUS
        Kd = intrinsics_from_fov(args.size, args.size, 2.5 * np.arcsin(RADIUS / dist))
        R, t = look_at([0.0, 0.0, dist], CENTER)
        view = ProbeView("front", _render(mi, truth, ball, _sensor(mi, Kd, R, t, args.size), args.spp),
                         Kd, R, t)
        row = {}
        for label in ("pinhole+fresnel", "orthographic+fresnel"):
            rec, w = unwrap_view(view, CENTER, RADIUS, dirs, **variants[label])
            row[label] = _errors(rec, w, truth)["weight>0.3"]
        results["distance_sweep"][f"{radii}_radii"] = row
        print(f"{radii:3d} radii: median error pinhole {row['pinhole+fresnel']['median_relative']:.4f}"
              f"  orthographic {row['orthographic+fresnel']['median_relative']:.4f}", flush=True)

    with tempfile.TemporaryDirectory() as work:
        capture = save_capture(Path(work) / "capture", views, images)
        out = Path(work) / "probe.exr"
        cmd = [sys.executable, "-m", "abs.cli.main", "probe", "unwrap", str(capture.folder),
               "--center", ",".join(map(str, CENTER)), "--radius", str(RADIUS), "--width", str(mw),
               "--fresnel", str(chrome_path), "--out", str(out)]
        subprocess.run(cmd, check=True, cwd=ROOT)
        cli_map = read_image(out)
        results["cli_matches_api"] = float(np.abs(cli_map - merged_maps["pinhole+fresnel"][0]).max())

    # A scene lit by the recovered map (unrecovered texels are black) and by the true one.
    scene = {"diffuse": {"type": "sphere", "center": [-0.06, 0, 0], "radius": 0.05,
                         "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.7}}},
             "metal": {"type": "sphere", "center": [0.06, 0, 0], "radius": 0.05,
                       "bsdf": {"type": "roughconductor", "alpha": 0.2, "material": "Al"}}}
    R, t = look_at([0.0, 0.1, 0.5], [0.0, 0.0, 0.0])
    sensor = _sensor(mi, intrinsics_from_fov(96, 96, np.radians(30)), R, t, 96)
    lit_true = _render(mi, truth, scene, sensor, 256)
    results["relit_scene"] = {}
    for label in ("pinhole+fresnel", "pinhole", "orthographic+fresnel"):
        lit = _render(mi, merged_maps[label][0], scene, sensor, 256)
        rmse = float(np.sqrt(np.mean((lit - lit_true) ** 2)))
        results["relit_scene"][label] = {"rmse": rmse, "relative_rmse": rmse / float(lit_true.mean())}
        print(f"relit with {label:28s} RMSE {rmse:.4f} ({rmse / lit_true.mean():.3f} of the mean)")
    # The same scene rendered twice from the true map with different seeds: the noise floor.
    scene_noise = _render(mi, truth, scene, sensor, 256) - lit_true  # same seed: exactly 0
    results["relit_scene"]["note"] = ("96x96, 256 spp, same seed for every map, so Monte-Carlo "
                                      f"noise largely cancels (same-seed difference {np.abs(scene_noise).max():.1e})")
    path = ROOT / "benchmarks" / "results" / "probe_unwrap.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
