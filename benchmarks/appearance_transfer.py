"""Material appearance across renderers (issue 29): characterise, transfer, score on held-out scenes.

Renderer A is abs's path tracer. Each target renderer B (:mod:`abs.appearance.renderers`) is
characterised on the characterisation design (7 classes x 2 samples x 4 wall colourings = 56
Cornell-box scenes, one sphere each) under the shared royal_esplanade map, and so is A. Then each
held-out scene (:func:`abs.appearance.design.heldout_design`: 3 spheres of held-out samples, new
positions, wall colours never seen) is rendered by A and by B, A's image is transferred to B's
look, and the result is scored against B's own image with the structured-light study's metric
(Reinhard, gamma 2.2, CIELAB, CIEDE2000; :mod:`abs.appearance.score`), over the object pixels of
the non-glass spheres (glass apart), as pixel mean ± sd and as the θ-profile ΔE00 that averages
Monte-Carlo noise away.

Targets: ``abs`` with other seeds (identity), ``gains`` (a known per-channel filter: its gains
must come back within 2 %), ``mitsuba`` (stock ``path``, max_depth 3, alpha = roughness², thin
glass, white balance and exposure) and ``camera`` (vignetting, colour matrix, response curve).
Methods: the statistics transfer with no / per-class / global colour matrix, with the spread
term, and global / local histogram matching.

Scaled down from the paper (120 scenes, 5 samples per class) to run in about 10 minutes on two
CPU cores: 64x64 pixels, 64 spp for the characterisation, 512 spp for the held-out images.

    python benchmarks/appearance_transfer.py [--size 64 --spp 64 --heldout-spp 512]

Writes ``benchmarks/results/appearance_transfer.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
TARGETS = {"abs": {}, "gains": {"gains": [1.2, 1.0, 0.75]}, "mitsuba": {}, "camera": {}}
METHODS = ("before", "statistics", "statistics+class-matrix", "statistics+global-matrix",
           "statistics+spread", "histogram-global", "histogram-local")


def _apply(method, image, geometry, a, b):
    from abs.appearance import transfer
    from abs.appearance.histogram import match_global, match_local

    if method == "before":
        return image
    if method == "histogram-global":
        return match_global(image, geometry, b)
    if method == "histogram-local":
        return match_local(image, geometry, b)
    matrix = {"statistics+class-matrix": "class", "statistics+global-matrix": "global"}.get(method, "none")
    return transfer(image, geometry, a, b, colour_matrix=matrix, spread=method.endswith("spread"))


def _scene_score(image, target, geometry):
    """Pixel ΔE00 (mean, sd) over the non-glass objects, their pixel-weighted profile ΔE00, and
    each glass object's (mean, profile)."""
    from abs.appearance.score import delta_e_map, object_scores

    delta = delta_e_map(image, target)
    objects = object_scores(image, target, geometry)
    solid = [o for o in objects if o["class"] != "glass"]
    mask = np.isin(geometry.ids, [o["object"] for o in solid])
    n = np.array([o["pixels"] for o in solid], float)
    return {"mean": float(delta[mask].mean()), "sd": float(delta[mask].std()),
            "profile": float(np.sum(n * [o["profile"] for o in solid]) / n.sum()),
            "objects": objects,
            "glass": [{"mean": o["mean"], "profile": o["profile"]} for o in objects if o["class"] == "glass"]}


def main() -> None:
    from abs.appearance import characterise, characterisation_design, heldout_design, renderer
    from abs.appearance.environment import load_environment
    from abs.appearance.scenes import design_camera, scene_geometry

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--heldout-spp", type=int, default=512)
    parser.add_argument("--out", type=Path, default=RESULTS / "appearance_transfer.json")
    args = parser.parse_args()
    start = time.time()
    env, env_name = load_environment(None)
    design = characterisation_design(2)
    timings = {}

    def timed(name, fn):
        t = time.time()
        out = fn()
        timings[name] = round(time.time() - t, 1)
        print(f"{name}: {timings[name]} s", flush=True)
        return out

    a = timed("characterise abs", lambda: characterise(renderer("abs"), design, env, size=args.size,
                                                        spp=args.spp, seed=0))
    chars = {name: timed(f"characterise target {name}", lambda name=name, opts=opts: characterise(
        renderer(name, opts), design, env, size=args.size, spp=args.spp, seed=10000 * (i + 1)))
        for i, (name, opts) in enumerate(TARGETS.items())}

    camera = design_camera(args.size)
    heldout = heldout_design()
    sources = {}
    for i, spec in enumerate(heldout):
        sources[spec.name] = (renderer("abs").render(spec, env, camera, args.heldout_spp, 7 + i),
                              scene_geometry(spec, camera))
    table = {}
    for t, (name, opts) in enumerate(TARGETS.items()):
        b = chars[name]
        rows = {m: [] for m in METHODS}
        for i, spec in enumerate(heldout):
            image, geometry = sources[spec.name]
            target = renderer(name, opts).render(spec, env, camera, args.heldout_spp, 100 + 10 * t + i)
            for m in METHODS:
                rows[m].append({"scene": spec.name, **_scene_score(_apply(m, image, geometry, a, b),
                                                                     target, geometry)})
        table[name] = rows
        print(f"{name}: " + ", ".join(f"{m} {np.mean([r['mean'] for r in rows[m]]):.2f}/"
                                      f"{np.mean([r['profile'] for r in rows[m]]):.2f}" for m in METHODS),
              flush=True)

    weights = a.counts[..., None].astype(float)
    gains = (np.nansum(weights * chars["gains"].alpha, axis=(0, 1))
             / np.nansum(weights * a.alpha, axis=(0, 1)))
    true_gains = np.array(TARGETS["gains"]["gains"])

    def verdict(rows, method, key):
        before = [r[key] for r in rows["before"]]
        after = [r[key] for r in rows[method]]
        return {"reduction_per_scene": [round(1 - y / x, 3) for x, y in zip(before, after)],
                "every_scene_30pct": all(y <= 0.7 * x for x, y in zip(before, after)),
                "no_scene_worse": all(y <= x for x, y in zip(before, after))}

    criteria = {
        "gains_recovered": {"true": true_gains.tolist(), "measured": gains.round(4).tolist(),
                            "max_relative_error": float(np.max(np.abs(gains / true_gains - 1))),
                            "within_2pct": bool(np.all(np.abs(gains / true_gains - 1) < 0.02))},
        "identity": {key: {"noise_floor": float(np.mean([r[key] for r in table["abs"]["before"]])),
                           "after": float(np.mean([r[key] for r in table["abs"]["statistics"]])),
                           "within_floor_plus_0.1": bool(
                               np.mean([r[key] for r in table["abs"]["statistics"]])
                               <= np.mean([r[key] for r in table["abs"]["before"]]) + 0.1)}
                     for key in ("mean", "profile")},
    }
    for name in ("mitsuba", "camera"):
        criteria[name] = {m: {key: verdict(table[name], m, key) for key in ("mean", "profile")}
                          for m in METHODS[1:]}
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = None
    summary = {"commit": commit, "environment": env_name,
               "settings": {"size": args.size, "spp": args.spp, "heldout_spp": args.heldout_spp,
                            "characterisation_scenes": len(design), "heldout_scenes": len(heldout)},
               "timings_s": {**timings, "total": round(time.time() - start, 1)},
               "criteria": criteria, "table": table}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(json.dumps({"criteria": criteria, "timings_s": summary["timings_s"]}, indent=1))


if __name__ == "__main__":
    main()
