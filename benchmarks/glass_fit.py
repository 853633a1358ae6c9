"""Glass in front of the checkerboard, fitted on photographs that abs did not render.

Each case renders a capture of the default scene's set-up (tablecloth, printed checkerboard,
environment) with a glass object of known IOR and absorption, by **plain Mitsuba**: the stock
``dielectric`` (one IOR for all channels), a homogeneous absorbing medium inside it, ``envmap`` and
the ``volpath`` integrator, never abs's own path tracer, at ``--photo-spp`` (4096) samples per
pixel and :data:`PHOTO_GLASS_SPP_FACTOR` (16) times that where the glass is seen: a photograph has
no Monte-Carlo noise, and a render's is heavy-tailed through glass (measured over replicate
photographs, ``benchmarks/glass_photo_noise.py``, ``docs/fitting.md``, Uncertainty). Sensor noise
is added, the last view is a holdout view. The scene file handed to the fit starts from IOR 1.5 (the last case: 1.75),
absorption 1/1/1 per metre and environment scale 1; ``abs.fit`` then fits ``glass.absorption``,
``glass.ior`` and ``environment.scale`` as the glass recipe does (``fitting/glass_absorption_ior.py``:
short fits from several IORs choose the start, then ``SETTINGS``, IOR tied; the starts are
``abs.fit``'s own, ``FitSettings.starts``), unless ``--settings`` replaces the settings (then from
the scene file's values) or ``--single-start`` skips the starts.

A case with ``sensor`` is photographed instead through a simulated camera (barrel distortion, an
RGGB Bayer sensor, raw brackets with shot and read noise; the plain-Mitsuba renders at twice the
resolution behind it) and built into its capture by ``build_capture``, as a user's raw
photographs are; the fit then renders the build's processing exactly (``processing`` in
``cameras.json``). Its scale is reported in scene units (the sensor's gain divided out).

Reported per case: fitted values and standard errors against the truth, whether each truth lies
within two standard errors, holdout RMSE before/after, the fit's own checks, renders and time.

    python benchmarks/glass_fit.py [--cases sphere-1.52,...] [--width 120 --height 100]

Writes ``benchmarks/results/glass_fit.json`` (after every case; finished cases are skipped on a
rerun) and prints a table.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenes/default"
RESULTS = ROOT / "benchmarks/results/glass_fit.json"
FITTED = ["glass.absorption", "glass.ior", "environment.scale"]


@dataclass(frozen=True)
class Case:
    name: str
    mesh: str
    ior: float
    absorption_per_m: tuple[float, float, float]
    env_scale: float
    start_ior: float = 1.5  # the scene file's (the fit's start without the recipe's several starts)
    elevation_deg: float = 20.0  # the cameras' (abs.simulate.place_cameras)
    object_fraction: float = 0.5  # of the vertical field of view the object's bounding sphere spans
    # Photographed by a simulated camera instead: barrel distortion, an RGGB Bayer sensor, 12-bit
    # raw brackets with shot and read noise, built into the capture by `abs capture build`
    # (bilinear demosaicing, undistortion; benchmarks/acquisition.py's end-to-end sensor).
    sensor: bool = False
    # ... and the build told the simulated camera's point-spread function (``lens_blur_px`` in the
    # build file, then the capture's ``processing``), as a user who measured the lens's would.
    psf_known: bool = False


CASES = [
    Case("sphere-1.52", "sphere.ply", 1.523, (6.0, 2.5, 1.0), 1.6),  # the failed fit
    Case("sphere-1.47", "sphere.ply", 1.47, (0.0, 0.0, 0.0), 1.0),
    Case("sphere-1.62", "sphere.ply", 1.62, (2.0, 5.0, 9.0), 1.2),
    Case("bowl-1.52", "bowl.ply", 1.52, (6.0, 2.5, 1.0), 1.3),
    # The same bowl framed as a photographer frames glass before a pattern: low cameras see the
    # checkerboard through it (from 20 degrees they see the cloth), and it spans more pixels.
    Case("bowl-1.52-framed", "bowl.ply", 1.52, (6.0, 2.5, 1.0), 1.3, elevation_deg=5.0,
         object_fraction=0.9),
    # A start in the wrong basin: one fit from 1.75 ended at 1.646 +- 0.007 with no check.
    Case("sphere-1.47-from-1.75", "sphere.ply", 1.47, (0.0, 0.0, 0.0), 1.0, start_ior=1.75),
    # The sphere photographed through a raw sensor and built as a user's photographs are.
    Case("sphere-1.52-raw", "sphere.ply", 1.523, (6.0, 2.5, 1.0), 1.6, sensor=True),
    Case("sphere-1.52-raw-psf", "sphere.ply", 1.523, (6.0, 2.5, 1.0), 1.6, sensor=True,
         psf_known=True),
]

#: The sensor of ``Case.sensor`` cases: data numbers per second per unit of scene radiance. The
#: built capture's values, and so the fitted ``environment.scale``, carry this factor.
SENSOR_GAIN = 2.0e5
#: The simulated camera's blur beyond a site's square, sensor pixels: a site's value is made from
#: a render at twice the resolution (Mitsuba's tent filter, variance 1/6 of a fine pixel^2 =
#: 1/24 of a site's), resampled bilinearly at the distorted positions (on average 1/24 more) and
#: averaged over 2 x 2 fine samples (1/16 where the square's box has 1/12): 1/16 in all beyond
#: the box, a Gaussian of standard deviation 1/4.
SIMULATED_LENS_BLUR_PX = 0.25


def _raw_capture(case: Case, folder: Path, args) -> None:
    """The case's capture photographed by a simulated camera (``Case.sensor``): plain Mitsuba
    renders at twice the resolution resampled through barrel distortion, mosaiced, exposed as
    12-bit raw brackets (built into the capture by :func:`_build`)."""
    import shutil

    from abs.render import compile_scene
    from abs.scene import load_scene
    from abs.simulate import place_cameras

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from acquisition import E2E, _e2e_raw_brackets

    compiled = compile_scene(load_scene(folder / "truth.toml"))
    views = place_cameras(compiled, args.views, args.width, args.height,
                          elevation_deg=case.elevation_deg, object_fraction=case.object_fraction)
    cfg = {**E2E, "width": args.width, "height": args.height, "views": args.views,
           "truth_spp": args.photo_spp, "gain_dn_per_s": SENSOR_GAIN, "truth_seed": 1}
    for sub in ("raw", "capture"):
        shutil.rmtree(folder / sub, ignore_errors=True)
    raw = _e2e_raw_brackets(compiled, views, folder / "raw", cfg, noise_seed=1,
                            render=mitsuba_photograph)
    if case.psf_known:
        # As a user with a measured point-spread function writes it into the build file.
        build = json.loads((raw / "build.json").read_text())
        (raw / "build.json").write_text(json.dumps({**build, "lens_blur_px": SIMULATED_LENS_BLUR_PX}))


def _build(folder: Path) -> None:
    """The case's raw brackets built into its capture, afresh (seconds: every run builds with
    the current build, the photographs' renders are what is cached)."""
    import shutil

    from abs.acquisition.build import build_capture

    shutil.rmtree(folder / "capture", ignore_errors=True)
    build_capture(folder / "raw" / "build.json", folder / "capture")



def _scene_text(mesh: str, ior, absorption, scale: float) -> str:
    text = (DEFAULT / "scene.toml").read_text()
    text = text.replace('mesh = "sphere.ply"              # radius 0.04, centre (0, 0.04, 0): rests on the cloth',
                        f'mesh = "{(DEFAULT / mesh).as_posix()}"')
    for asset in ("env.exr", "cloth.ply", "backdrop.ply", "checkerboard.png"):
        text = text.replace(f'"{asset}"', f'"{(DEFAULT / asset).as_posix()}"')
    text = text.replace("ior = [1.515, 1.52, 1.53]", f"ior = {list(map(float, ior))}")
    text = text.replace("absorption = [4.0, 1.5, 2.5]", f"absorption = {list(map(float, absorption))}")
    text = text.replace("scale = 1.0       # radiance multiplier", f"scale = {scale}       # radiance multiplier")
    assert f'"{(DEFAULT / mesh).as_posix()}"' in text
    return text


#: The photographs take this many times their samples per pixel where the glass is seen (the
#: rectangle of :func:`abs.model.observations.seen_rectangle`). A photograph has no Monte-Carlo
#: noise, and a render's is worst through glass: at 4096 spp the distant bowl's photographs held
#: 10-30 times the sensor's noise variance in the bowl's pixels, about its level elsewhere
#: (``benchmarks/glass_photo_noise.py``), and the fit, which takes one noise level for all pixels,
#: reported a quarter of the error that noise made.
PHOTO_GLASS_SPP_FACTOR = 16


def mitsuba_photograph(compiled, camera, spp: int, seed: int,
                       glass_spp_factor: int = PHOTO_GLASS_SPP_FACTOR) -> np.ndarray:
    """Plain Mitsuba's rendering of a compiled abs scene from ``camera``: stock ``dielectric``
    (the green IOR for every channel) with a homogeneous absorbing medium inside, ``volpath``;
    the rectangle where glass is seen rendered again (a cropped film, its own seed) at
    ``glass_spp_factor`` times ``spp`` and pasted in."""
    import mitsuba as mi

    from abs.model.observations import seen_rectangle

    d = compiled.mitsuba_dict()
    glass = compiled.scene.materials["glass"]
    sigma = np.asarray(glass.absorption_per_m, float)
    peak = float(sigma.max())
    d["glass"] = {"type": "dielectric", "int_ior": float(glass.ior_rgb[1]), "ext_ior": 1.0, "id": "glass"}
    for obj in compiled.scene.objects:
        if obj.material == "glass" and peak > 0:
            # RGB sigma_t above 1 is refused in a scene dictionary: scale carries the magnitude.
            d[compiled.shape_ids[obj.name]]["interior"] = {
                "type": "homogeneous", "albedo": 0.0, "scale": peak,
                "sigma_t": {"type": "rgb", "value": (sigma / peak).tolist()}}
    d["integrator"] = {"type": "volpath", "max_depth": compiled.scene.render.max_depth}
    w, h = camera.width, camera.height
    to_world = np.eye(4)
    to_world[:3, :3] = camera.R.T @ np.diag([-1.0, -1.0, 1.0])  # OpenCV camera axes -> Mitsuba's
    to_world[:3, 3] = camera.center

    def render(crop: dict, samples: int, render_seed: int) -> np.ndarray:
        d["sensor"] = {"type": "perspective", "fov_axis": "y",
                       "fov": float(np.degrees(2 * np.arctan(h / 2 / camera.K[1, 1]))),
                       "to_world": mi.ScalarTransform4f(to_world),
                       "film": {"type": "hdrfilm", "width": w, "height": h,
                                "rfilter": {"type": "tent"}, "pixel_format": "rgb", **crop}}
        return np.array(mi.render(mi.load_dict(d, optimize=False), spp=samples, seed=render_seed),
                        np.float32)

    image = render({}, spp, seed)
    rectangle = seen_rectangle(camera, compiled.transmissive_bounds()) if glass_spp_factor > 1 else None
    if rectangle is not None:
        x0, y0, x1, y1 = rectangle
        # sample_border: the crop's edge pixels take their filter's samples from outside it too,
        # as in the full image.
        image[y0:y1, x0:x1] = render({"crop_offset_x": x0, "crop_offset_y": y0, "crop_width": x1 - x0,
                                      "crop_height": y1 - y0, "sample_border": True},
                                     spp * glass_spp_factor, seed + 7_919)
    return image


def _truth(case: Case) -> dict:
    return {"ior": case.ior, "absorption_per_m": list(case.absorption_per_m), "env_scale": case.env_scale,
            "mesh": case.mesh, "elevation_deg": case.elevation_deg, "object_fraction": case.object_fraction}


def run_case(case: Case, work: Path, args) -> dict:
    from abs.fitting import fit
    from abs.scene import load_scene
    from abs.simulate import simulate_capture

    folder = work / case.name
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth.toml").write_text(_scene_text(case.mesh, [case.ior] * 3, case.absorption_per_m,
                                                   case.env_scale))
    # A built capture's values are data numbers per second: the start (and truth) of the scale
    # carry the sensor's gain, the start still 1 in scene units.
    unit = SENSOR_GAIN if case.sensor else 1.0
    (folder / "scene.toml").write_text(_scene_text(case.mesh, [case.start_ior] * 3, (1.0, 1.0, 1.0),
                                                   unit))
    # The mesh's bytes key the cached capture too: an edited asset (the bowl lifted off the cloth)
    # renders a new one.
    shape = {"views": args.views, "width": args.width, "height": args.height, "photo_spp": args.photo_spp,
             "photo_glass_spp_factor": PHOTO_GLASS_SPP_FACTOR,
             "mesh_sha256": hashlib.sha256((DEFAULT / case.mesh).read_bytes()).hexdigest(),
             **({"sensor_gain": SENSOR_GAIN} if case.sensor else {}),
             **({"lens_blur_px": SIMULATED_LENS_BLUR_PX} if case.psf_known else {})}
    made = folder / "capture" / "benchmark.json"
    if case.sensor:
        # The raw brackets are cached (raw/benchmark.json; captures built before the build wrote
        # noise images kept the record in capture/), the capture is built on every run.
        recorded = folder / "raw" / "benchmark.json"
        if not recorded.exists() and made.exists() and (folder / "raw").is_dir():
            recorded.write_text(made.read_text())
        if not recorded.exists() or json.loads(recorded.read_text()) != {**shape, "truth": _truth(case)}:
            _raw_capture(case, folder, args)
            recorded.write_text(json.dumps({**shape, "truth": _truth(case)}))
        _build(folder)
        made.write_text(recorded.read_text())
    elif not made.exists() or json.loads(made.read_text()) != {**shape, "truth": _truth(case)}:
        simulate_capture(load_scene(folder / "truth.toml"), folder / "capture", n_cameras=args.views,
                         width=args.width, height=args.height, spp=args.photo_spp, shot_noise=1e-4,
                         read_noise=0.003, seed=1, render=mitsuba_photograph,
                         elevation_deg=case.elevation_deg, object_fraction=case.object_fraction)
        made.write_text(json.dumps({**shape, "truth": _truth(case)}))
    settings = _settings(args.settings)
    if args.single_start:
        settings = dataclasses.replace(settings, starts=())
    start = time.perf_counter()

    def progress(state):
        print(f"  {case.name}: iteration {state.iteration}, RMSE {state.history[-1]['loss']:.4g}, "
              f"{time.perf_counter() - start:.0f} s", flush=True)

    result = fit(folder / "scene.toml", folder / "capture", FITTED, settings, on_iteration=progress,
                 truth={"glass.absorption": list(case.absorption_per_m), "glass.ior": [case.ior] * 3,
                        "environment.scale": [case.env_scale * unit]})
    summary = result.summary()
    rows = {}
    for name in FITTED:
        entry = summary["parameters"][name]
        value, stderr, truth = (np.array(entry[k], float) if entry[k] is not None else None
                                for k in ("value", "stderr", "truth"))
        stderr = np.array([np.nan if s is None else s for s in entry["stderr"]], float)
        if name == "environment.scale":  # in scene units
            value, stderr, truth = value / unit, stderr / unit, truth / unit
        rows[name] = {"value": value.tolist(), "stderr": [None if not np.isfinite(s) else s for s in stderr],
                      "truth": truth.tolist(), "error": (value - truth).tolist(),
                      "covered_2se": [bool(abs(v - t) <= 2 * s) if np.isfinite(s) else False
                                      for v, t, s in zip(value, truth, stderr)],
                      # The refinement's steps cut to the trust radius (the noise-walk check's).
                      "refinement_limited": entry.get("refinement_limited")}
    return {"case": case.name, "mesh": case.mesh, "sensor": case.sensor, "parameters": rows, "checks": summary["checks"],
            "holdout_rmse": summary["holdout_rmse"], "image_noise": summary["image_noise"],
            "renders": summary["renders"], "fit_wall_s": time.perf_counter() - start,
            "starts": summary.get("starts"), "difference_steps": summary.get("difference_steps"),
            "polish": summary.get("polish"),
            "trace": [{"iteration": h["iteration"], "loss": h["loss"], "values": h["values"]}
                      for h in result.history],
            "settings": {**shape, "fit": dataclasses.asdict(settings)}}


def _settings(text: str):
    """``--settings`` JSON as :class:`abs.FitSettings`, or the glass recipe's when it is empty."""
    from abs.fitting import FitSettings

    def frozen(value):  # JSON's lists as the nested tuples FitSettings holds (schedules, starts)
        return tuple(map(frozen, value)) if isinstance(value, list) else value

    given = json.loads(text)
    if given:
        return FitSettings(**{k: frozen(v) for k, v in given.items()})
    sys.path.insert(0, str(ROOT / "fitting"))
    from glass_absorption_ior import settings

    return settings("glass")


def table(results: list[dict]) -> list[str]:
    lines = ["| case | IOR fitted (truth) | absorption 1/m fitted (truth) | scale (truth) | "
             "within 2 se | holdout RMSE | checks | fit time |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        p = r["parameters"]
        fmt = lambda name: ", ".join(f"{v:.3g}" for v in p[name]["value"])  # noqa: E731
        truth = lambda name: ", ".join(f"{v:.3g}" for v in p[name]["truth"])  # noqa: E731
        covered = sum(sum(p[n]["covered_2se"]) for n in p)
        total = sum(len(p[n]["covered_2se"]) for n in p)
        lines.append(f"| {r['case']} | {fmt('glass.ior')} ({truth('glass.ior')}) | "
                     f"{fmt('glass.absorption')} ({truth('glass.absorption')}) | "
                     f"{fmt('environment.scale')} ({truth('environment.scale')}) | {covered}/{total} | "
                     f"{r['holdout_rmse']['before']:.3f} -> {r['holdout_rmse']['after']:.3f} | "
                     f"{len(r['checks'])} | {r['fit_wall_s'] / 60:.1f} min |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="all")
    parser.add_argument("--width", type=int, default=120)
    parser.add_argument("--height", type=int, default=100)
    parser.add_argument("--views", type=int, default=5)
    parser.add_argument("--photo-spp", type=int, default=4096)
    parser.add_argument("--work", type=Path, default=ROOT / "out/glass-fit")
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--single-start", action="store_true",
                        help="fit from the scene file's values only (not the recipe's starts)")
    parser.add_argument("--settings", default="{}",
                        help="FitSettings fields as JSON (default: the glass recipe's settings)")
    args = parser.parse_args()
    chosen = CASES if args.cases == "all" else [c for c in CASES if c.name in args.cases.split(",")]
    done = json.loads(args.results.read_text()) if args.results.exists() else []
    finished = {r["case"] for r in done}
    for case in chosen:
        if case.name in finished:
            continue
        print(f"{case.name}: the capture rendered with plain Mitsuba (unless cached in --work), "
              "then the fit", flush=True)
        done.append(run_case(case, args.work, args))
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(done, indent=2))
        print("\n".join(table(done[-1:])), flush=True)
    print("\n".join(table(done)))


if __name__ == "__main__":
    main()
