"""``abs lightstage calibrate|measure|fit|render``: light calibration and per-point reflectance
from a light-stage session.

- ``calibrate CALIB --geometry G``: LED positions from a mirror ball's highlights, the ``cos^m``
  radial attenuation and RGB intensities from a grey board (the calibration folder's
  ``calibration.json``), written as a refined geometry file (default ``CALIB/geometry.json``) and
  a report ``CALIB/calibration-report.json``; ``measure --geometry`` then uses it;

- ``measure SESSION``: every LED frame's pixels onto the mesh (needs the rig's ``geometry.json``
  and the object's mesh; a session from ``abs rig capture --simulate`` carries both) into
  ``OUT/measurements.npz`` (default OUT: ``SESSION/lightstage``);
- ``fit OUT``: Lambert, Blinn-Phong and Cook-Torrance per surface point and channel, into
  ``OUT/fits.npz`` and ``OUT/fit.json`` (converged fractions, median parameters);
- ``render OUT``: the held-out views and lights rendered from each fitted model, with the thesis's
  Eq. 4.1 MAE into ``OUT/evaluation.json`` (and the first renders as EXR under ``OUT/renders``).

See docs/lightstage.md.
"""

from __future__ import annotations

import json
from pathlib import Path

from abs.errors import InputError

META = "lightstage.json"

# Thesis Table 4.1: MAE of held-out renders, pixel values in [0, 1].
THESIS_TABLE_4_1 = {
    "coin": {"lambert": 0.02979, "blinn_phong": 0.03074, "cook_torrance": 0.21930},
    "rock": {"lambert": 0.02339, "blinn_phong": 0.02470, "cook_torrance": 0.12989},
    "PCB": {"lambert": 0.04383, "blinn_phong": 0.04364, "cook_torrance": 0.19217},
    "box": {"lambert": 0.03743, "blinn_phong": 0.03845, "cook_torrance": 0.15958},
}


def add_parser(sub) -> None:
    p = sub.add_parser("lightstage", help="light stage: per-point reflectance from a capture session")
    commands = p.add_subparsers(dest="lightstage_command", required=True)

    c = commands.add_parser("calibrate", help="refine the rig geometry file's LEDs from mirror-ball "
                            "and grey-board frames")
    c.add_argument("folder", type=Path, help="calibration folder (calibration.json and its frames)")
    c.add_argument("--geometry", type=Path, required=True, help="the rig's geometry file (as designed)")
    c.add_argument("--out", type=Path, help="refined geometry file (default FOLDER/geometry.json)")
    c.add_argument("--sigma-prior-mm", type=float, default=20.0,
                   help="uncertainty of the geometry file's LED positions, mm (default %(default)s)")
    c.add_argument("--sigma-direction-rad", type=float, default=None,
                   help="uncertainty of a highlight line's direction, radians (default: estimated "
                        "per LED from its lines' scatter)")
    c.set_defaults(run=run_calibrate)

    m = commands.add_parser("measure", help="project every LED frame's pixels onto the mesh")
    m.add_argument("session", type=Path, help="session folder (abs rig capture)")
    m.add_argument("--geometry", type=Path, help="rig geometry file (default SESSION/geometry.json)")
    m.add_argument("--mesh", type=Path, help="object mesh, object frame, metres (default SESSION/mesh.ply)")
    m.add_argument("--out", type=Path, help="light-stage folder (default SESSION/lightstage)")
    m.add_argument("--spacing", type=float, default=0.01,
                   help="surface point spacing, metres (default %(default)s)")
    m.add_argument("--max-depth", type=int, default=6,
                   help="deepest per-triangle subdivision (default %(default)s)")
    m.add_argument("--holdout-every", type=int, default=5,
                   help="hold out light group (position p, LED k) when (p + k) %% N == 0; 0: none "
                        "(default %(default)s)")
    m.set_defaults(run=run_measure)

    f = commands.add_parser("fit", help="fit Lambert, Blinn-Phong and Cook-Torrance per point")
    f.add_argument("folder", type=Path, help="light-stage folder (from measure)")
    f.add_argument("--min-measurements", type=int, default=8,
                   help="points with fewer measurements are not fitted (default %(default)s)")
    f.add_argument("--max-measurements", type=int, default=400,
                   help="fit each point to at most this many of its measurements, drawn at random "
                        "(default %(default)s)")
    f.set_defaults(run=run_fit)

    r = commands.add_parser("render", help="render held-out views and lights; MAE (thesis Eq. 4.1)")
    r.add_argument("folder", type=Path, help="light-stage folder (from fit)")
    r.add_argument("--write", type=int, default=4, help="write the first N held-out frames' renders "
                   "as EXR (default %(default)s)")
    r.set_defaults(run=run_render)


def _meta(folder: Path) -> dict:
    from abs.errors import read_json

    path = folder / META
    if not path.exists():
        raise InputError(path, "", "not found: run 'abs lightstage measure' first")
    return read_json(path, what="light-stage folder file")


def _need(path: Path, step: str) -> Path:
    if not path.exists():
        raise InputError(path, "", f"not found: run 'abs lightstage {step}' first")
    return path


def run_calibrate(args) -> int:
    from abs.lightstage.calibration import calibrate, read_calibration
    from abs.lightstage.geometry import read_geometry, write_geometry

    for name in ("sigma_prior_mm", "sigma_direction_rad"):
        if getattr(args, name) is not None and not getattr(args, name) > 0:
            raise InputError(None, "--" + name.replace("_", "-"), f"must be > 0, got {getattr(args, name)}")
    geometry = read_geometry(args.geometry)
    data = read_calibration(args.folder)
    refined, report = calibrate(geometry, data, args.sigma_prior_mm * 1e-3, args.sigma_direction_rad)
    out = args.out or args.folder / "geometry.json"
    write_geometry(refined, out)
    report = {"geometry_in": str(args.geometry.resolve()), "geometry_out": str(out.resolve()),
              "ball_frames": len(data.ball_frames), "board_frames": len(data.board_frames), **report}
    (args.folder / "calibration-report.json").write_text(json.dumps(report, indent=1) + "\n")
    shifts = [v["shift_mm"] for v in report["leds"].values() if "shift_mm" in v]
    if shifts:
        print(f"LED positions: {len(shifts) - len(report['leds_without_highlight'])} refined, median shift "
              f"{sorted(shifts)[len(shifts) // 2]:.2f} mm")
    if "attenuation" in report:
        print(f"attenuation cos^{report['attenuation']['exponent']:.3f} (board up to "
              f"{report['attenuation']['measured_up_to_deg']:.1f} deg off axis); intensities of "
              f"{len(report['leds']) - len(report['leds_without_board'])} LEDs")
    print(f"wrote {out}")
    return 0


def run_measure(args) -> int:
    from abs.lightstage.geometry import read_geometry
    from abs.lightstage.measure import groups_json, measure
    from abs.lightstage.pipeline import load_mesh, prepare
    from abs.lightstage.session import read_session_groups

    session = args.session
    groups = read_session_groups(session)
    geometry_path = args.geometry or session / "geometry.json"
    if not geometry_path.exists():
        raise InputError(geometry_path, "", "rig geometry file not found (give --geometry; "
                         "'abs rig capture --simulate' writes one)")
    geometry = read_geometry(geometry_path)
    mesh_path = args.mesh or session / "mesh.ply"
    mesh = load_mesh(mesh_path)
    if not args.spacing > 0:
        raise InputError(None, "--spacing", f"must be > 0, got {args.spacing}")
    tracer, points = prepare(mesh, args.spacing, args.max_depth)
    meas = measure(geometry, tracer, points, groups, holdout_every=args.holdout_every, log=print)
    if len(meas) == 0:
        raise InputError(session, "frames", "no pixel of any LED frame lands lit on the mesh: "
                         "check the geometry file and the mesh's frame")
    out = args.out or session / "lightstage"
    out.mkdir(parents=True, exist_ok=True)
    meas.save(out / "measurements.npz")
    (out / "groups.json").write_text(groups_json(groups, geometry, args.holdout_every) + "\n")
    meta = {"format": "abs-lightstage/1", "session": str(session.resolve()),
            "geometry": str(geometry_path.resolve()), "mesh": str(Path(mesh_path).resolve()),
            "spacing_m": args.spacing, "max_depth": args.max_depth, "holdout_every": args.holdout_every,
            "points": len(points), "measurements": len(meas),
            "held_out_measurements": int(meas.held_out.sum()), "groups": len(groups)}
    (out / META).write_text(json.dumps(meta, indent=1) + "\n")
    print(f"{out}: {len(meas)} measurements ({meta['held_out_measurements']} held out) from "
          f"{len(groups)} light groups on {len(points)} surface points")
    return 0


def _load(folder: Path):
    from abs.lightstage.geometry import read_geometry
    from abs.lightstage.pipeline import load_mesh, prepare

    meta = _meta(folder)
    geometry = read_geometry(meta["geometry"])
    tracer, points = prepare(load_mesh(meta["mesh"]), float(meta["spacing_m"]), int(meta["max_depth"]))
    return meta, geometry, tracer, points


def run_fit(args) -> int:
    from abs.lightstage.measure import Measurements
    from abs.lightstage.pipeline import fit_measurements, parameter_summary

    meta = _meta(args.folder)
    meas = Measurements.load(_need(args.folder / "measurements.npz", "measure"))
    fits = fit_measurements(meas, int(meta["points"]), args.min_measurements, args.max_measurements,
                            progress=lambda k, n: print(f"fitted {k}/{n} points", flush=True))
    fits.save(args.folder / "fits.npz")
    summary = {"converged_fraction": fits.converged_fraction(),
               "points_fitted": int((fits.count > 0).sum()), "points": int(meta["points"]),
               "median_parameters": parameter_summary(fits)}
    (args.folder / "fit.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary["converged_fraction"]))
    return 0


def run_render(args) -> int:
    import numpy as np

    from abs.errors import read_json
    from abs.io.images import read_image, write_exr
    from abs.lightstage.fit import ModelFits
    from abs.lightstage.models import MODELS
    from abs.lightstage.pipeline import evaluate_held_out
    from abs.lightstage.render import fitted_reflectance

    meta, geometry, tracer, points = _load(args.folder)
    fits = ModelFits.load(_need(args.folder / "fits.npz", "fit"))
    groups = read_json(_need(args.folder / "groups.json", "measure"), expect=list)
    frames = [(g["camera"], g["angle_deg"], g["light"], g["level"], t, f)
              for g in groups if g["held_out"] for f, t in zip(g["files"], g["exposures_s"])]
    if not frames:
        raise InputError(args.folder / "groups.json", "held_out", "no held-out frames (measure with "
                         "--holdout-every > 0)")
    renders = args.folder / "renders"
    renders.mkdir(exist_ok=True)

    def on_render(k: int, model: str, image: np.ndarray) -> None:
        if k < args.write:
            write_exr(renders / f"{k:04d}-{model}.exr", image.astype(np.float32))

    stream = ((c, a, light, lvl, t, read_image(f)) for c, a, light, lvl, t, f in frames)
    result = evaluate_held_out(geometry, tracer, stream,
                               {m: fitted_reflectance(fits, m, points) for m in MODELS}, on_render)
    evaluation = {"mae_eq_4_1": result, "held_out_frames": len(frames),
                  "converged_fraction": fits.converged_fraction(),
                  "thesis_table_4_1": THESIS_TABLE_4_1}
    (args.folder / "evaluation.json").write_text(json.dumps(evaluation, indent=1) + "\n")
    for m, v in result.items():
        print(f"{m}: held-out MAE {v:.5f} over {len(frames)} frames")
    return 0
