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
glass, white balance and exposure), ``camera`` (vignetting, colour matrix, response curve),
``mitsuba-spectral`` (the ``mitsuba`` target rendered in ``llvm_ad_spectral``) and ``spectral``
(stock Mitsuba in ``llvm_ad_spectral`` with every other setting at abs's: max_depth 8, alpha =
roughness, solid glass, no white balance or exposure).
Methods: the statistics transfer (λ as a per-bin ratio, the default; and as the additive shift it
replaced) with no / per-class / global colour matrix, with the spread term, with the normal step;
the sensor step alone and before the statistics; global / local histogram matching.

Where the per-pixel error comes from: for the methods in ``BREAKDOWN``, the pixel ΔE00 over all
held-out non-glass object pixels split by class, θ bin, brightness (the target pixel's luminance
over its object's median) and image radius (over the half-diagonal), each with its share of the
summed error; the identity target's "before" is the noise floor.

Scaled down from the paper (120 scenes, 5 samples per class) to run in about 10 minutes on two
CPU cores (the two spectral targets add about 7, a worker process per image): 64x64 pixels, 64 spp for the characterisation, 512 spp for the held-out images.

    python benchmarks/appearance_transfer.py [--size 64 --spp 64 --heldout-spp 512]
    python benchmarks/appearance_transfer.py --targets mitsuba,mitsuba-spectral,spectral \
        --out benchmarks/results/appearance_transfer_spectral.json

Writes ``benchmarks/results/appearance_transfer.json`` (every target) or ``--out``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
# Target name -> (registered renderer, options). Seeds follow a target's position here, so a new
# target goes at the end and a run of some targets (``--targets``) renders what the full run does.
TARGETS = {"abs": ("abs", {}), "gains": ("gains", {"gains": [1.2, 1.0, 0.75]}),
           "mitsuba": ("mitsuba", {}), "camera": ("camera", {}),
           "mitsuba-spectral": ("mitsuba", {"spectral": True}),
           "spectral": ("mitsuba", {"spectral": True, "max_depth": 8, "squared_roughness": False,
                                    "thin_glass": False, "white_balance": [1.0, 1.0, 1.0],
                                    "exposure": 1.0})}


def _methods():
    """Method name -> ``f(image, geometry, a, b, sensor)`` (``sensor``: the target's fitted step)."""
    from abs.appearance import transfer
    from abs.appearance.histogram import match_global, match_local

    def stats(**kw):
        return lambda image, geometry, a, b, sensor: transfer(image, geometry, a, b, **kw)

    return {
        "before": lambda image, geometry, a, b, sensor: image,
        "statistics": stats(),
        "statistics-additive": stats(shift="additive"),
        "statistics+class-matrix": stats(colour_matrix="class"),
        "statistics+global-matrix": stats(colour_matrix="global"),
        "statistics+spread": stats(spread=True),
        "statistics+normals": stats(normals=True),
        "sensor": lambda image, geometry, a, b, sensor: transfer(image, geometry, a, b, sensor=sensor,
                                                                  theta=False),
        "sensor+statistics": lambda image, geometry, a, b, sensor: transfer(image, geometry, a, b,
                                                                             sensor=sensor),
        "histogram-global": lambda image, geometry, a, b, sensor: match_global(image, geometry, b),
        "histogram-local": lambda image, geometry, a, b, sensor: match_local(image, geometry, b),
    }


METHODS = ("before", "statistics", "statistics-additive", "statistics+class-matrix",
           "statistics+global-matrix", "statistics+spread", "statistics+normals", "sensor",
           "sensor+statistics", "histogram-global", "histogram-local")
BREAKDOWN = ("before", "statistics", "statistics-additive", "statistics+normals", "sensor")
_BRIGHTNESS = (0.0, 0.5, 1.0, 2.0, 4.0, np.inf)  # target luminance over its object's median
_RADIUS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.01)  # distance from the image centre over the half-diagonal


def _pixels(image, target, geometry):
    """Per non-glass object pixel: ΔE00, class, θ bin, relative brightness, radius, and whether
    the result went below zero in some channel."""
    from abs.appearance.score import delta_e_map
    from abs.appearance.sensor import image_radius2
    from abs.appearance.statistics import object_bins, theta_edges

    delta = delta_e_map(image, target)
    radius = np.sqrt(image_radius2(*image.shape[:2]))
    rows = []
    for obj, mask, bins in object_bins(geometry, theta_edges(9)):
        cls = geometry.classes[obj - 1]
        if cls == "glass":
            continue
        lum = target[mask] @ np.array([0.2126, 0.7152, 0.0722])
        rows.append({"delta": delta[mask], "class": np.full(mask.sum(), cls), "bin": bins,
                     "brightness": lum / max(float(np.median(lum)), 1e-12), "radius": radius[mask],
                     "negative": (image[mask] < 0).any(-1)})
    return {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}


def _split(p):
    """Mean ΔE00 and share of the summed error by class, θ bin, brightness and radius."""
    total = p["delta"].sum()

    def part(select):
        n = int(select.sum())
        return {"pixels": n, "mean": round(float(p["delta"][select].mean()), 3) if n else None,
                "share": round(float(p["delta"][select].sum() / total), 3)}

    return {"mean": round(float(p["delta"].mean()), 3), "sd": round(float(p["delta"].std()), 3),
            "p90": round(float(np.percentile(p["delta"], 90)), 3),
            "negative_pixels": int(p["negative"].sum()),
            "class": {c: part(p["class"] == c) for c in sorted(set(p["class"]))},
            "theta_bin_deg": {f"{10 * b}-{10 * b + 10}": part(p["bin"] == b) for b in sorted(set(p["bin"]))},
            "brightness": {f"{lo}-{hi}": part((p["brightness"] >= lo) & (p["brightness"] < hi))
                           for lo, hi in zip(_BRIGHTNESS[:-1], _BRIGHTNESS[1:])},
            "radius": {f"{lo}-{hi}": part((p["radius"] >= lo) & (p["radius"] < hi))
                       for lo, hi in zip(_RADIUS[:-1], _RADIUS[1:])}}


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
    from abs.appearance.transfer import normal_step, sensor_step

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--heldout-spp", type=int, default=512)
    parser.add_argument("--targets", default=",".join(TARGETS),
                        help=f"comma-separated subset of {', '.join(TARGETS)}")
    parser.add_argument("--out", type=Path, default=None,
                        help="results file (default benchmarks/results/appearance_transfer.json, "
                             "which only a run of every target may write)")
    args = parser.parse_args()
    names = [n.strip() for n in args.targets.split(",") if n.strip()]
    unknown = [n for n in names if n not in TARGETS]
    if unknown or not names:
        parser.error(f"--targets: unknown {unknown}; expected some of {', '.join(TARGETS)}")
    if args.out is None:
        if set(names) != set(TARGETS):
            parser.error("--out is required with a subset of --targets (the main results file "
                         "holds every target)")
        args.out = RESULTS / "appearance_transfer.json"
    index = {name: i for i, name in enumerate(TARGETS)}  # seeds as in the full run
    targets = {name: TARGETS[name] for name in TARGETS if name in names}
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
    chars = {name: timed(f"characterise target {name}", lambda r=r, opts=opts, name=name: characterise(
        renderer(r, opts), design, env, size=args.size, spp=args.spp, seed=10000 * (index[name] + 1)))
        for name, (r, opts) in targets.items()}

    camera = design_camera(args.size)
    heldout = heldout_design()
    sources = {}
    for i, spec in enumerate(heldout):
        sources[spec.name] = (renderer("abs").render(spec, env, camera, args.heldout_spp, 7 + i),
                              scene_geometry(spec, camera))
    table, breakdown, steps = {}, {}, {}
    methods = _methods()
    for name, (r, opts) in targets.items():
        t = index[name]
        b = chars[name]
        sensor = timed(f"sensor step {name}", lambda b=b: sensor_step(a, b))
        steps[name] = {"sensor": sensor.to_json(), "normal_step_split_test": normal_step(a, b)[1]}
        rows = {m: [] for m in METHODS}
        pixels = {m: [] for m in BREAKDOWN}
        for i, spec in enumerate(heldout):
            image, geometry = sources[spec.name]
            target = timed(f"held-out {name} {spec.name}", lambda r=r, opts=opts, spec=spec, t=t, i=i: renderer(
                r, opts).render(spec, env, camera, args.heldout_spp, 100 + 10 * t + i))
            for m in METHODS:
                out = methods[m](image, geometry, a, b, sensor)
                rows[m].append({"scene": spec.name, **_scene_score(out, target, geometry)})
                if m in BREAKDOWN:
                    pixels[m].append(_pixels(out, target, geometry))
        table[name] = rows
        breakdown[name] = {m: _split({k: np.concatenate([p[k] for p in pixels[m]]) for k in pixels[m][0]})
                           for m in BREAKDOWN}
        print(f"{name}: " + ", ".join(f"{m} {np.mean([r['mean'] for r in rows[m]]):.2f}/"
                                      f"{np.mean([r['profile'] for r in rows[m]]):.2f}" for m in METHODS),
              flush=True)

    weights = a.counts[..., None].astype(float)

    def verdict(rows, method, key):
        before = [r[key] for r in rows["before"]]
        after = [r[key] for r in rows[method]]
        return {"reduction_per_scene": [round(1 - y / x, 3) for x, y in zip(before, after)],
                "every_scene_30pct": all(y <= 0.7 * x for x, y in zip(before, after)),
                "no_scene_worse": all(y <= x for x, y in zip(before, after))}

    criteria = {}
    if "gains" in targets:
        gains = (np.nansum(weights * chars["gains"].alpha, axis=(0, 1))
                 / np.nansum(weights * a.alpha, axis=(0, 1)))
        true_gains = np.array(TARGETS["gains"][1]["gains"])
        criteria["gains_recovered"] = {
            "true": true_gains.tolist(), "measured": gains.round(4).tolist(),
            "max_relative_error": float(np.max(np.abs(gains / true_gains - 1))),
            "within_2pct": bool(np.all(np.abs(gains / true_gains - 1) < 0.02))}
    if "abs" in targets:
        criteria["identity"] = {
            key: {"noise_floor": float(np.mean([r[key] for r in table["abs"]["before"]])),
                  "after": float(np.mean([r[key] for r in table["abs"]["statistics"]])),
                  "within_floor_plus_0.1": bool(
                      np.mean([r[key] for r in table["abs"]["statistics"]])
                      <= np.mean([r[key] for r in table["abs"]["before"]]) + 0.1)}
            for key in ("mean", "profile")}
    for name in [n for n in targets if n not in ("abs", "gains")]:
        criteria[name] = {m: {key: verdict(table[name], m, key) for key in ("mean", "profile")}
                          for m in METHODS[1:]}
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = None
    summary = {"commit": commit, "environment": env_name,
               "targets": {name: {"renderer": r, "options": opts} for name, (r, opts) in targets.items()},
               "settings": {"size": args.size, "spp": args.spp, "heldout_spp": args.heldout_spp,
                            "characterisation_scenes": len(design), "heldout_scenes": len(heldout)},
               "timings_s": {**timings, "total": round(time.time() - start, 1)},
               "criteria": criteria, "steps": steps, "breakdown": breakdown, "table": table}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(json.dumps({"criteria": criteria, "timings_s": summary["timings_s"]}, indent=1))


if __name__ == "__main__":
    main()
