"""Image-based material editing against rendered truth (issue 30): baseline vs analysis by synthesis.

A sphere (radius 5 cm) in a real HDR environment (``../shared/data/polyhaven_hdri_1k/``) is
rendered with abs's path tracer as the "photograph": an orange rough plastic (Mitsuba
``roughplastic``, diffuse reflectance (0.6, 0.3, 0.15), GGX alpha 0.1). The same sphere with
the target material, same camera, seed and environment, is the truth. The photograph and the
sphere's mask (ray-cast coverage) go to :func:`abs.editing.edit` and its result is scored
against the truth over the sphere's pixels:

- CIEDE2000, mean and sd over the sphere's pixels, after the structured-light study's tone
  mapping (:mod:`abs.studies.sl_scoring`: Reinhard's global operator with key 0.18 on the
  log-average luminance of the *true* image, 2.2 gamma; both images mapped identically);
- SSIM (:func:`abs.metrics.ssim`) over the sphere's pixels, both images scaled by the truth's
  auto exposure (99th percentile of luminance to 0.9), so that highlights do not all clip.

The edits and their truths:

| edit | truth |
|---|---|
| ``glossier`` | the same plastic with alpha 0.02 |
| ``diffuse`` | the same plastic with alpha 0.4 |
| ``merl:NAME`` | the MERL material NAME (``abs_tabulated``, the shared neural fit) |
| ``glass:clear`` | smooth glass, IOR 1.5 (``abs_dielectric``) |
| ``glass:tinted`` | the same glass absorbing (2, 12, 30) 1/m (orange) |
| ``glass:frosted`` | rough glass, Beckmann alpha 0.15 |
| ``translucent`` | rough glass, alpha 0.6 (a stand-in: abs renders no subsurface scattering here) |

Two methods are scored: ``baseline`` (Khan et al. 2006, :mod:`abs.editing`) and ``synthesis``
(:mod:`abs.resynthesis`: the photograph fitted with abs's renderer, the target rendered in the
fitted scene). The synthesis fit does not depend on the edit, so it is made once
(:func:`abs.resynthesis.fit_photograph`) and each edit renders from it
(:func:`abs.resynthesis.edit_fitted`), exactly what ``edit(..., method="synthesis")`` does per
call. It is told the camera's field of view (24 degrees), which one photograph does not give.

Scaled down for two shared cores: one shape (the sphere), one environment, 96x72 pixels.
Writes ``benchmarks/results/material_edit.json`` and a montage PNG (photograph, truth, baseline,
synthesis per row).

    python benchmarks/material_edit.py [--width 96 --height 72 --spp 64 --merl gold-metallic-paint]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
ORIGINAL = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.1,
            "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.3, 0.15]}}


def truth_bsdfs(merl: str) -> dict[str, dict]:
    """Mitsuba BSDF dicts of the truths, by edit spec."""
    plastic = lambda alpha: {**ORIGINAL, "alpha": alpha}  # noqa: E731
    glass = lambda **kw: {"type": "abs_dielectric", "ior": 1.5, **kw}  # noqa: E731
    return {"glossier": plastic(0.02), "diffuse": plastic(0.4),
            f"merl:{merl}": {"type": "abs_tabulated", "id": "brdf"},
            "glass:clear": glass(), "glass:tinted": glass(absorption=[2.0, 12.0, 30.0]),
            "glass:frosted": glass(roughness=0.15), "translucent": glass(roughness=0.6)}


class Studio:
    """The sphere, camera and environment shared by every rendering."""

    def __init__(self, environment: np.ndarray, width: int, height: int, spp: int, seed: int):
        import drjit as dr
        import mitsuba as mi

        from abs.camera.pinhole import intrinsics_from_fov, look_at
        from abs.render.bsdfs import dielectric as _dielectric  # noqa: F401  (registers it)
        from abs.render.bsdfs import tabulated as _tabulated  # noqa: F401  (registers it)
        from abs.render.camera import Camera
        from abs.render.environment import Environment

        self.mi, self.dr = mi, dr
        self.width, self.height, self.spp, self.seed = width, height, spp, seed
        self.environment = Environment(environment)
        # Camera on -z looking along +z at the sphere (the view abs.editing's map assumes).
        R, t = look_at(np.array([0.0, 0.0, -0.35]), np.zeros(3))
        self.camera = Camera(intrinsics_from_fov(width, height, np.deg2rad(24.0)), R, t,
                             width, height)

    def scene(self, bsdf: dict):
        return self.mi.load_dict({"type": "scene", "sphere": {"type": "sphere", "radius": 0.05,
                                                              "bsdf": bsdf}})

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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=72)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--map", default="polyhaven_hdri_1k/royal_esplanade_1k.hdr",
                        help="environment, relative to the shared data folder")
    parser.add_argument("--merl", default="gold-metallic-paint", help="MERL material of merl:NAME")
    parser.add_argument("--edits", help="comma-separated subset of the edits")
    parser.add_argument("--fit-spp", type=int, default=8, help="samples per pixel of the synthesis fit")
    parser.add_argument("--methods", default="baseline,synthesis")
    parser.add_argument("--out", type=Path, default=RESULTS / "material_edit.json")
    args = parser.parse_args(argv)

    from abs.render.variant import set_variant

    set_variant()
    from abs.brdf.measured import measured_table
    from abs.editing.spec import parse_material
    from abs.colour.tonemap import tonemap
    from abs.editing import EditSettings, edit
    from abs.editing.edit import estimate
    from abs.resynthesis import SynthesisSettings, edit_fitted, fit_photograph
    from abs.io.images import read_image, write_png
    from abs.io.shared_data import shared_data_dir

    environment = read_image(shared_data_dir() / args.map)
    studio = Studio(environment, args.width, args.height, args.spp, args.seed)
    mask = studio.mask()
    start = time.time()
    photo = studio.render(ORIGINAL)
    print(f"photograph: {args.width}x{args.height}, {args.spp} spp, {mask.sum()} object pixels, "
          f"{time.time() - start:.1f} s")
    methods = [m.strip() for m in args.methods.split(",")]
    syn = SynthesisSettings(fov_deg=24.0, fit_spp=args.fit_spp, render_spp=args.spp, seed=args.seed)
    fitted, fit_s = None, None
    if "synthesis" in methods:
        start = time.time()
        fitted = fit_photograph(photo, mask, estimate(photo, mask, EditSettings()), syn)
        fit_s = round(time.time() - start, 1)
        print(f"synthesis fit: {fit_s} s, trust {fitted.trust}")
    bsdfs = truth_bsdfs(args.merl)
    chosen = [e.strip() for e in args.edits.split(",")] if args.edits else list(bsdfs)
    rows, tiles = {}, []
    from abs.colour.tonemap import auto_exposure

    exposure = auto_exposure(photo)
    for spec in chosen:
        if spec not in bsdfs:
            parser.error(f"unknown edit {spec!r}; choose from {', '.join(bsdfs)}")
        start = time.time()
        table = measured_table(spec.split(":", 1)[1]) if spec.startswith("merl:") else None
        truth = studio.render(bsdfs[spec], table)
        t_render = time.time() - start
        rows[spec] = {"render_s": round(t_render, 2), "unedited": score(photo, truth, mask)}
        images = {}
        for method in methods:
            start = time.time()
            images[method] = (edit(photo, mask, spec).image if method == "baseline"
                              else edit_fitted(photo, mask, parse_material(spec), fitted, syn))
            rows[spec][method] = {**score(images[method], truth, mask),
                                  "edit_s": round(time.time() - start, 2)}
        r = rows[spec]
        print(f"{spec:24s} " + "  ".join(
            f"{m} dE00 {r[m]['de00_mean']:6.2f} ± {r[m]['de00_sd']:5.2f} SSIM {r[m]['ssim']:.3f}"
            for m in methods) + f"   (as is: dE00 {r['unedited']['de00_mean']:6.2f}, "
                                f"SSIM {r['unedited']['ssim']:.3f})")
        tiles.append(np.concatenate([tonemap(photo, exposure), tonemap(truth, exposure)]
                                    + [tonemap(images[m], exposure) for m in methods], axis=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    summary = {"settings": {"width": args.width, "height": args.height, "spp": args.spp,
                            "seed": args.seed, "map": args.map, "original": ORIGINAL,
                            "object_pixels": int(mask.sum())},
               "methods": {"baseline": "Khan et al. 2006, abs.editing defaults",
                           "synthesis": "abs.resynthesis defaults but fov_deg 24 (the camera's) "
                                        f"and fit_spp {args.fit_spp}, render_spp {args.spp}"},
               "synthesis_fit": None if fitted is None else {**fitted.trust, "fit_s": fit_s},
               "edits": rows}
    args.out.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    if tiles:
        write_png(args.out.with_suffix(".png"), np.concatenate(tiles, axis=0))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
