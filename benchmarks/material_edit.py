"""Image-based material editing against rendered truth (issue 30): baseline vs analysis by synthesis.

An object in a real HDR environment (``../shared/data/``: Poly Haven and Blender maps) is
rendered with abs's path tracer as the "photograph". The same object with the target material,
same camera, seed and environment, is the truth. The photograph and the object's mask (ray-cast
coverage) go to :func:`abs.editing.edit` and its result is scored against the truth over the
object's pixels:

- CIEDE2000, mean and sd over the object's pixels, after the structured-light study's tone
  mapping (:mod:`abs.studies.sl_scoring`: Reinhard's global operator with key 0.18 on the
  log-average luminance of the *true* image, 2.2 gamma; both images mapped identically);
- SSIM (:func:`abs.metrics.ssim`) over the object's pixels, both images scaled by the truth's
  auto exposure (99th percentile of luminance to 0.9), so that highlights do not all clip.

Scenes (:data:`SCENES`): shapes (a sphere, an ellipsoid), original materials (rough plastics
of three colours and roughnesses) and environments. The edits and their truths, in the amounts
the synthesis method uses (:mod:`abs.resynthesis.materials`), so that the benchmark scores the
rendering of an edit, not the guess of how much glossier "glossier" is:

| edit | truth |
|---|---|
| ``glossier`` | the original plastic, alpha / ``GLOSSIER_FACTOR`` |
| ``diffuse`` | the original plastic, alpha x ``DIFFUSE_FACTOR`` |
| ``merl:NAME`` | the MERL material NAME (``abs_tabulated``, the shared neural fit) |
| ``glass:clear`` | smooth glass, IOR 1.5 (``abs_dielectric``) |
| ``glass:tinted`` | the same glass absorbing so that the transmittance across the object's largest extent is the original's reflectance over its largest channel |
| ``glass:frosted`` | rough glass, Beckmann alpha ``FROSTED_ROUGHNESS`` |
| ``translucent`` | rough glass, alpha ``TRANSLUCENT_ROUGHNESS`` (a stand-in: abs renders no subsurface scattering here) |

Two methods are scored: ``baseline`` (Khan et al. 2006, :mod:`abs.editing`) and ``synthesis``
(:mod:`abs.resynthesis`: the photograph fitted with abs's renderer, the target rendered in the
fitted scene). The synthesis fit does not depend on the edit, so it is made once per scene
(:func:`abs.resynthesis.fit_photograph`) and each edit renders from it
(:func:`abs.resynthesis.edit_fitted`), exactly what ``edit(..., method="synthesis")`` does per
call. It is told the camera's field of view (24 degrees), which one photograph does not give.

Scaled for two shared cores: 96x72 pixels, 256 spp (a photograph has no Monte-Carlo noise: at
64 spp the sun's highlight in the photograph was itself sparkling noise, and on one seed of three
it looked like a coating of twice the roughness to the synthesis method's highlight test).
Writes ``benchmarks/results/material_edit.json``
and a montage PNG (photograph, truth, baseline, synthesis per row; scenes one after another).

    python benchmarks/material_edit.py [--scenes NAME,... --width 96 --height 72 --spp 256]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
RADIUS_M = 0.05  # of the sphere; the ellipsoid's semi-axes are this times its ``axes``


def _plastic(alpha: float, rgb: tuple[float, float, float]) -> dict:
    return {"type": "roughplastic", "distribution": "ggx", "alpha": alpha,
            "diffuse_reflectance": {"type": "rgb", "value": list(rgb)}}


SCENES = {
    "sphere-orange-esplanade": {"axes": (1.0, 1.0, 1.0), "original": _plastic(0.1, (0.6, 0.3, 0.15)),
                                "map": "polyhaven_hdri_1k/royal_esplanade_1k.hdr"},
    "ellipsoid-blue-overpass": {"axes": (1.3, 0.8, 1.0), "original": _plastic(0.05, (0.1, 0.2, 0.5)),
                                "map": "polyhaven_hdri_1k/pedestrian_overpass_1k.hdr"},
    "sphere-green-courtyard": {"axes": (1.0, 1.0, 1.0), "original": _plastic(0.2, (0.2, 0.45, 0.15)),
                               "map": "blender_studiolights_world_cc0/courtyard.exr"},
}
"""Benchmark scenes: the object's semi-axes (times ``RADIUS_M``), original material, map."""


def truth_bsdfs(original: dict, diameter_m: float, merl: str) -> dict[str, dict]:
    """Mitsuba BSDF dicts of the truths, by edit spec (module docstring)."""
    from abs.resynthesis.materials import (DIFFUSE_FACTOR, FROSTED_ROUGHNESS, GLASS_IOR,
                                           GLOSSIER_FACTOR, TRANSLUCENT_ROUGHNESS)

    alpha = original["alpha"]
    rho = np.asarray(original["diffuse_reflectance"]["value"], float)
    plastic = lambda a: {**original, "alpha": a}  # noqa: E731
    glass = lambda **kw: {"type": "abs_dielectric", "ior": GLASS_IOR, **kw}  # noqa: E731
    return {"glossier": plastic(alpha / GLOSSIER_FACTOR),
            "diffuse": plastic(min(alpha * DIFFUSE_FACTOR, 1.0)),
            f"merl:{merl}": {"type": "abs_tabulated", "id": "brdf"},
            "glass:clear": glass(),
            "glass:tinted": glass(absorption=(-np.log(rho / rho.max()) / diameter_m).tolist()),
            "glass:frosted": glass(roughness=FROSTED_ROUGHNESS),
            "translucent": glass(roughness=TRANSLUCENT_ROUGHNESS)}


class Studio:
    """The object (an ellipsoid mesh about the origin), camera and environment of one scene."""

    def __init__(self, environment: np.ndarray, axes: tuple[float, float, float], width: int,
                 height: int, spp: int, seed: int, folder: Path):
        import drjit as dr
        import mitsuba as mi
        import trimesh

        from abs.camera.pinhole import intrinsics_from_fov, look_at
        from abs.render.bsdfs import dielectric as _dielectric  # noqa: F401  (registers it)
        from abs.render.bsdfs import tabulated as _tabulated  # noqa: F401  (registers it)
        from abs.render.camera import Camera
        from abs.render.environment import Environment

        self.mi, self.dr = mi, dr
        self.width, self.height, self.spp, self.seed = width, height, spp, seed
        self.environment = Environment(environment)
        mesh = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS_M)
        mesh.apply_scale(np.asarray(axes, float))
        self.mesh_file = Path(folder) / "object.ply"
        mesh.export(self.mesh_file)
        self.diameter_m = float(2 * RADIUS_M * max(axes))
        # Camera on -z looking along +z at the object (the view abs.editing's map assumes).
        R, t = look_at(np.array([0.0, 0.0, -0.35]), np.zeros(3))
        self.camera = Camera(intrinsics_from_fov(width, height, np.deg2rad(24.0)), R, t,
                             width, height)

    def scene(self, bsdf: dict):
        return self.mi.load_dict({"type": "scene", "object": {
            "type": "ply", "filename": str(self.mesh_file), "bsdf": bsdf}})

    def mask(self) -> np.ndarray:
        mi, dr = self.mi, self.dr
        scene = self.scene({"type": "diffuse"})
        idx = dr.arange(mi.UInt32, self.width * self.height)
        origin, d = self.camera.rays(mi.Float(idx % self.width), mi.Float(idx // self.width))
        hit = scene.ray_intersect(mi.Ray3f(origin, d)).is_valid()
        return np.asarray(hit, bool).reshape(self.height, self.width)

    def render(self, bsdf: dict, table: np.ndarray | None = None) -> np.ndarray:
        from abs.render.integrator import PathTracer
        from abs.render.jit import from_numpy

        scene = self.scene(bsdf)
        if table is not None:
            params = self.mi.traverse(scene)
            key = next(k for k in params.keys() if k.endswith("table"))  # noqa: SIM118
            params[key] = from_numpy(self.mi.Float, np.maximum(np.asarray(table, np.float32), 0.0))
            params.update()
        image = PathTracer(max_depth=12).render(scene, self.environment, self.camera, self.spp,
                                                seed=self.seed)
        return np.asarray(image, np.float32)


def score(edited: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict:
    """CIEDE2000 (mean, sd) after the study's tone mapping and SSIM, over ``mask``."""
    from abs.colour.tonemap import auto_exposure
    from abs.metrics import ssim
    from abs.studies.sl_scoring import ciede2000_image, log_average_luminance, reinhard

    log_average = log_average_luminance(truth)
    delta = ciede2000_image(reinhard(truth, log_average), reinhard(edited, log_average))[mask]
    exposure = auto_exposure(truth)
    return {"de00_mean": float(delta.mean()), "de00_sd": float(delta.std()),
            "ssim": ssim(edited * exposure, truth * exposure, mask)}


def run_scene(name: str, args, methods: list[str], tiles: list) -> dict:
    """Photograph, synthesis fit, and every edit of one scene, scored; the montage rows appended."""
    import tempfile

    from abs.brdf.measured import measured_table
    from abs.colour.tonemap import auto_exposure, tonemap
    from abs.editing import EditSettings, edit
    from abs.editing.edit import estimate
    from abs.editing.spec import parse_material
    from abs.io.images import read_image
    from abs.io.shared_data import shared_data_dir
    from abs.resynthesis import SynthesisSettings, edit_fitted, fit_photograph

    definition = SCENES[name]
    environment = read_image(shared_data_dir() / definition["map"])
    with tempfile.TemporaryDirectory(prefix="abs-bench-") as tmp:
        studio = Studio(environment, definition["axes"], args.width, args.height, args.spp,
                        args.seed, Path(tmp))
        mask = studio.mask()
        start = time.time()
        photo = studio.render(definition["original"])
        print(f"[{name}] photograph: {args.width}x{args.height}, {args.spp} spp, {mask.sum()} "
              f"object pixels, {time.time() - start:.1f} s")
        syn = SynthesisSettings(**{"fov_deg": 24.0, "fit_spp": args.fit_spp, "seed": args.seed,
                                   **args.synthesis})
        fitted, fit_s = None, None
        if "synthesis" in methods:
            start = time.time()
            fitted = fit_photograph(photo, mask, estimate(photo, mask, EditSettings()), syn)
            fit_s = round(time.time() - start, 1)
            trust = fitted.trust
            print(f"[{name}] synthesis fit: {fit_s} s, reflectance "
                  f"{np.round(trust['reflectance'], 3).tolist()}, roughness {trust['roughness']}, "
                  f"residual {trust['residual_rmse']:.4f} ({trust['noise_ratio']:.1f} x noise)")
        bsdfs = truth_bsdfs(definition["original"], studio.diameter_m, args.merl)
        chosen = [e.strip() for e in args.edits.split(",")] if args.edits else list(bsdfs)
        rows = {}
        exposure = auto_exposure(photo)
        for spec in chosen:
            if spec not in bsdfs:
                raise SystemExit(f"unknown edit {spec!r}; choose from {', '.join(bsdfs)}")
            start = time.time()
            table = measured_table(spec.split(":", 1)[1]) if spec.startswith("merl:") else None
            truth = studio.render(bsdfs[spec], table)
            rows[spec] = {"render_s": round(time.time() - start, 2),
                          "unedited": score(photo, truth, mask)}
            images = {}
            for method in methods:
                start = time.time()
                images[method] = (edit(photo, mask, spec).image if method == "baseline"
                                  else edit_fitted(photo, mask, parse_material(spec), fitted, syn))
                rows[spec][method] = {**score(images[method], truth, mask),
                                      "edit_s": round(time.time() - start, 2)}
            r = rows[spec]
            print(f"[{name}] {spec:24s} " + "  ".join(
                f"{m} dE00 {r[m]['de00_mean']:6.2f} ± {r[m]['de00_sd']:5.2f} SSIM {r[m]['ssim']:.3f}"
                for m in methods) + f"   (as is: dE00 {r['unedited']['de00_mean']:6.2f}, "
                                    f"SSIM {r['unedited']['ssim']:.3f})", flush=True)
            tiles.append(np.concatenate([tonemap(photo, exposure), tonemap(truth, exposure)]
                                        + [tonemap(images[m], exposure) for m in methods], axis=1))
    return {"settings": {**definition, "object_pixels": int(mask.sum()),
                         "diameter_m": studio.diameter_m, "truths": bsdfs},
            "synthesis_fit": None if fitted is None else {**fitted.trust, "fit_s": fit_s},
            "edits": rows}


def summarise(scenes: dict, methods: list[str]) -> dict:
    """Per edit: each method's ΔE00 averaged over the scenes, and synthesis's change per scene."""
    edits = list(next(iter(scenes.values()))["edits"])
    out = {}
    for spec in edits:
        per = {m: [scenes[n]["edits"][spec][m]["de00_mean"] for n in scenes] for m in methods}
        entry = {f"{m}_de00_mean": float(np.mean(per[m])) for m in methods}
        if {"baseline", "synthesis"} <= set(methods):
            change = [s / b - 1 for s, b in zip(per["synthesis"], per["baseline"])]
            entry.update(change_per_scene=change,
                         change_of_means=entry["synthesis_de00_mean"]
                         / entry["baseline_de00_mean"] - 1,
                         synthesis_better_everywhere=all(c < 0 for c in change))
        out[spec] = entry
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", help=f"comma-separated subset of {', '.join(SCENES)}")
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=72)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--merl", default="gold-metallic-paint", help="MERL material of merl:NAME")
    parser.add_argument("--edits", help="comma-separated subset of the edits")
    parser.add_argument("--fit-spp", type=int, default=8, help="samples per pixel of the synthesis fit")
    parser.add_argument("--methods", default="baseline,synthesis")
    parser.add_argument("--synthesis", action="append", default=[], metavar="KEY=VALUE",
                        help="a SynthesisSettings field (JSON value), e.g. highlight_factor=20")
    parser.add_argument("--out", type=Path, default=RESULTS / "material_edit.json")
    args = parser.parse_args(argv)
    overrides = {}
    for item in args.synthesis:
        key, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--synthesis expects KEY=VALUE, got {item!r}")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parser.error(f"--synthesis {key}: {value!r} is not a JSON value")
        overrides[key] = tuple(parsed) if isinstance(parsed, list) else parsed
    args.synthesis = overrides
    names = [n.strip() for n in args.scenes.split(",")] if args.scenes else list(SCENES)
    for n in names:
        if n not in SCENES:
            parser.error(f"unknown scene {n!r}; choose from {', '.join(SCENES)}")

    from abs.render.variant import set_variant

    set_variant()
    from abs.io.images import write_png

    methods = [m.strip() for m in args.methods.split(",")]
    tiles: list = []
    start = time.time()
    scenes = {n: run_scene(n, args, methods, tiles) for n in names}
    summary = summarise(scenes, methods)
    for spec, entry in summary.items():
        print(f"{spec:24s} " + "  ".join(f"{m} {entry[f'{m}_de00_mean']:6.2f}" for m in methods)
              + (f"  change {100 * entry['change_of_means']:+.0f} % (per scene "
                 + ", ".join(f"{100 * c:+.0f}" for c in entry["change_per_scene"]) + " %)"
                 if "change_of_means" in entry else ""))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"settings": {"width": args.width, "height": args.height, "spp": args.spp,
                           "seed": args.seed, "fit_spp": args.fit_spp, "merl": args.merl},
              "methods": {"baseline": "Khan et al. 2006, abs.editing defaults",
                          "synthesis": "abs.resynthesis defaults but fov_deg 24 (the camera's) "
                                       f"and fit_spp {args.fit_spp}",
                          "synthesis_overrides": args.synthesis},
              "total_s": round(time.time() - start, 1), "summary": summary, "scenes": scenes}
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    if tiles:
        write_png(args.out.with_suffix(".png"), np.concatenate(tiles, axis=0))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
