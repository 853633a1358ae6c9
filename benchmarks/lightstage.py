"""Light-stage reflectance (issue 27, part 2): per-point Lambert, Blinn-Phong and Cook-Torrance fits
from a simulated dome, held-out MAE (thesis Eq. 4.1) beside the thesis's Table 4.1.

The simulated stage: the dome of rig/sim/optics.py (3 rings of 12 LEDs = 36 LEDs on a 0.5 m
hemisphere, elevations 15/35/55 degrees, each aimed at the centre with a cos^4 radial profile; one
camera 0.46 m away, 16 degree field of view) and a turntable of ``--positions`` stops (40 in the
thesis; 12 by default here for speed). The global light's frames serve photogrammetry only, which
is not simulated (the mesh is given), so they are not rendered.

Objects: spheres of 5 cm radius with known analytic, spatially varying reflectance:

- ``lambert_textured``: Lambert, albedo from rig/sim/optics.py's texture (eight coloured longitude
  segments, a darker equator band);
- ``blinn_phong_specular``: normalised Blinn-Phong, that texture x 0.6 as kd, ks = 0.3, e = 60;
- ``cook_torrance_specular``: GGX Cook-Torrance, texture x 0.6 as kd, ks = 0.4, alpha = 0.2;
- ``merl_box``: an 8 cm cube with regions of measured MERL materials (neural fits from
  ../shared/data/merl_nbrdf): gold-metallic-paint top, green-plastic upper and blue-rubber lower
  sides; no analytic truth, held-out MAE per region as well; with ``--basis B`` also abs's
  ``brdf_pca`` model fitted per point (abs.lightstage.pcafit).

Frames come from this project's own forward model of the dome (abs.lightstage.render: one ray per
pixel centre, shadow rays, inverse square and radial attenuation, no inter-reflection), on a finer
sphere mesh (icosphere level 5) than the one measured with (level 3, as a reconstructed mesh would
be coarser than the object), with noise (Gaussian, sigma 0.003 + 1 % of the value), a 3-exposure
bracket clipped at 1 per LED. Because rendering and evaluation share that model, the benchmark
tests measurement, normalisation, binning and fitting, not the light transport (documented in
docs/lightstage.md). A fifth of the light groups are held out ((position + LED) % 5 == 0); MAE is
over the object mask of every held-out frame (each exposure), pixel values in [0, 1].

    PYTHONPATH=. python benchmarks/lightstage.py [--positions 12] [--size 64x48] [--spacing 0.01]

benchmarks/results/lightstage.json is from ``--positions 40`` (the thesis size).

Writes benchmarks/results/lightstage.json.

Light calibration (issue 27, part 3), ``--calibration``: a true rig perturbed from the dome's
geometry file (abs.lightstage.calsim: LEDs moved by N(0, 8 mm) per axis, intensities x U(0.75, 1.25)
per LED and +-5 % per channel, a cos^10 profile where the file says cos^4), its simulated
mirror-ball frames (12 turntable stops, 8x the session's resolution) and grey-board frames; the
calibration's recovered positions, exponent and intensities against the truth; then the
``--calibration-object`` sphere captured by the true rig, measured and fitted three times: with the
geometry file as designed, with the calibrated geometry, and with the true geometry (the floor).
Writes benchmarks/results/lightstage_calibration.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import trimesh

from abs.lightstage.dome import dome_geometry
from abs.lightstage.measure import is_held_out, measure, pose_view
from abs.lightstage.models import MODELS, PARAMETERS
from abs.lightstage.pipeline import evaluate_held_out, fit_measurements, prepare
from abs.lightstage.raycast import MeshTracer
from abs.lightstage.render import AnalyticMaterial, fitted_reflectance, render_view
from abs.lightstage.session import LightGroup, merge_bracket

RESULTS = Path(__file__).resolve().parent / "results" / "lightstage.json"
CALIBRATION_RESULTS = RESULTS.with_name("lightstage_calibration.json")
RADIUS = 0.05
EXPOSURES = (0.0025, 0.01, 0.04)
THESIS_TABLE_4_1 = {
    "coin": {"lambert": 0.02979, "blinn_phong": 0.03074, "cook_torrance": 0.21930},
    "rock": {"lambert": 0.02339, "blinn_phong": 0.02470, "cook_torrance": 0.12989},
    "PCB": {"lambert": 0.04383, "blinn_phong": 0.04364, "cook_torrance": 0.19217},
    "box": {"lambert": 0.03743, "blinn_phong": 0.03845, "cook_torrance": 0.15958},
}


def texture(p: np.ndarray) -> np.ndarray:
    """rig/sim/optics.py's albedo texture (N, 3) at object points (copied: benchmarks do not
    depend on the rig package)."""
    longitude = np.arctan2(p[:, 0], p[:, 2])
    segment = np.floor((longitude + np.pi) / (2.0 * np.pi) * 8.0).astype(int) % 8
    palette = np.array([[0.8, 0.2, 0.2], [0.8, 0.6, 0.2], [0.6, 0.8, 0.2], [0.2, 0.8, 0.3],
                        [0.2, 0.7, 0.8], [0.2, 0.3, 0.8], [0.6, 0.2, 0.8], [0.8, 0.8, 0.8]])
    band = np.abs(p[:, 1]) < 0.2 * RADIUS
    return palette[segment] * np.where(band, 0.4, 1.0)[:, None]


def material(name: str) -> tuple[AnalyticMaterial, tuple[float, float] | None]:
    """The object's analytic material and its specular truth ``(ks, shape)``."""
    if name == "lambert_textured":
        return AnalyticMaterial("lambert", lambda p: texture(p)[:, :, None]), None
    model, ks, shape = {"blinn_phong_specular": ("blinn_phong", 0.3, 60.0),
                        "cook_torrance_specular": ("cook_torrance", 0.4, 0.2)}[name]

    def params_at(p: np.ndarray) -> np.ndarray:
        kd = 0.6 * texture(p)
        return np.stack([kd, np.full_like(kd, ks), np.full_like(kd, shape)], axis=2)

    return AnalyticMaterial(model, params_at), (ks, shape)


BOX_SIZE = 0.08
BOX_MATERIALS = ("gold-metallic-paint", "green-plastic", "blue-rubber")
"""The MERL box's regions: its top, the upper and the lower half of its sides (neural MERL fits,
../shared/data/merl_nbrdf, evaluated directly at each measurement's Rusinkiewicz angles)."""


def box_region(p: np.ndarray) -> np.ndarray:
    """Region index (N,) of object points on the box: 0 top, 1 upper sides, 2 lower sides."""
    top = p[:, 1] > 0.5 * BOX_SIZE - 1e-6
    return np.where(top, 0, np.where(p[:, 1] > 0.0, 1, 2))


def box_mesh():
    """An 8 cm cube on the turntable axis, each face with its own vertices (flat normals: a box's
    shared corner vertices would average the normals of three faces)."""
    box = trimesh.creation.box(extents=(BOX_SIZE,) * 3)
    box.unmerge_vertices()
    return box


def merl_box_material():
    from abs.brdf.nbrdf import evaluate_nbrdf, nbrdf_weights
    from abs.lightstage.render import MeasuredRegions

    weights = [nbrdf_weights(m) for m in BOX_MATERIALS]
    return MeasuredRegions(box_region, tuple(
        (lambda th, td, pd, w=w: evaluate_nbrdf(w, th, td, pd).astype(np.float64)) for w in weights))


def dome(width: int, height: int):
    boards, per_board, radius = 3, 12, 0.5
    pos = np.zeros((boards, per_board, 3))
    for b in range(boards):
        el = np.deg2rad(15.0 + 60.0 * b / boards)
        for i in range(per_board):
            az = 2.0 * np.pi * (i + 0.5 * (b % 2)) / per_board
            pos[b, i] = radius * np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    return dome_geometry(pos, np.array([0.0, 0.1, 0.45]), 16.0, width, height, 4.0, 1.0, 100.0)


def simulate(geometry, truth_tracer: MeshTracer, mat: AnalyticMaterial, positions: int,
             rng: np.random.Generator):
    """Light groups, their merged images and their raw bracket frames (held-out evaluation)."""
    groups, merged, raw = [], [], []
    for pos in range(positions):
        angle = 360.0 * pos / positions
        view = pose_view(geometry, truth_tracer, 0, angle)
        for light in sorted(geometry.leds):
            frames = []
            for t in EXPOSURES:
                clean = render_view(geometry, truth_tracer, view, light, 255, t, mat)  # clipped at 1
                # Noise on the clipped value, clipped again: a sensor at full well stays there.
                noisy = clean + rng.normal(size=clean.shape) * (0.003 + 0.01 * clean)
                frames.append(np.clip(noisy, 0.0, 1.0))
            groups.append(LightGroup(pos, angle, light, 255, (), EXPOSURES))
            merged.append(merge_bracket(frames, EXPOSURES))
            raw.append(frames)
    return groups, merged, raw


def run_object(name: str, args, geometry, truth_geometry=None) -> dict:
    """Simulate ``name`` with ``truth_geometry`` (default: ``geometry``), measure, fit and evaluate
    it with ``geometry``."""
    rng = np.random.default_rng(27)
    if name == "merl_box":
        return run_box(args, geometry, rng)
    mat, spec_truth = material(name)
    fine = trimesh.creation.icosphere(subdivisions=5, radius=RADIUS)
    truth_tracer = MeshTracer(fine.vertices, fine.faces, fine.vertex_normals)
    coarse = trimesh.creation.icosphere(subdivisions=3, radius=RADIUS)
    tracer, points = prepare(coarse, args.spacing)
    t0 = time.time()
    groups, merged, raw = simulate(truth_geometry or geometry, truth_tracer, mat, args.positions, rng)
    t_sim = time.time() - t0
    meas = measure(geometry, tracer, points, groups, merged)
    t_meas = time.time() - t0 - t_sim
    fits = fit_measurements(meas, len(points))
    t_fit = time.time() - t0 - t_sim - t_meas
    frames = [(0, g.angle_deg, g.light, 255, t, img)
              for g, imgs in zip(groups, raw) if is_held_out(g.position, g.light, geometry)
              for t, img in zip(EXPOSURES, imgs)]
    result = evaluate_held_out(geometry, tracer, frames,
                               {m: fitted_reflectance(fits, m, points) for m in MODELS})
    t_eval = time.time() - t0 - t_sim - t_meas - t_fit

    fitted = fits.count > 0
    truth = mat.params_at(points.position[fitted])
    recovered = {}
    for m in MODELS:
        p = fits.params[m][fitted]
        entry = {name_: {"median": np.nanmedian(p[:, :, i], axis=0).round(4).tolist()}
                 for i, name_ in enumerate(PARAMETERS[m])}
        if m == mat.model or m == "lambert" or spec_truth is None:
            kd_err = np.abs(p[:, :, 0] - truth[:, :, 0])
            entry["kd"]["median_abs_error_vs_truth"] = float(np.nanmedian(kd_err))
        if m == mat.model and spec_truth is not None:
            entry[PARAMETERS[m][1]]["truth"] = spec_truth[0]
            entry[PARAMETERS[m][2]]["truth"] = spec_truth[1]
            entry[PARAMETERS[m][1]]["median_abs_error_vs_truth"] = float(np.nanmedian(np.abs(p[:, :, 1] - spec_truth[0])))
            entry[PARAMETERS[m][2]]["median_rel_error_vs_truth"] = float(
                np.nanmedian(np.abs(p[:, :, 2] - spec_truth[1]) / spec_truth[1]))
        recovered[m] = entry
    out = {"true_model": mat.model, "specular_truth_ks_shape": spec_truth,
           "mae_eq_4_1_held_out": {m: round(v, 6) for m, v in result.items()},
           "converged_fraction": fits.converged_fraction(),
           "points": len(points), "points_fitted": int(fitted.sum()),
           "measurements": len(meas), "held_out_measurements": int(meas.held_out.sum()),
           "held_out_frames": len(frames),
           "median_measurements_per_fitted_point": float(np.median(fits.count[fitted])),
           "recovered_parameters": recovered,
           "seconds": {"simulate": round(t_sim, 1), "measure": round(t_meas, 1),
                       "fit": round(t_fit, 1), "evaluate": round(t_eval, 1)}}
    if spec_truth is not None:
        out["cook_torrance_beats_lambert"] = bool(result["cook_torrance"] < result["lambert"])
    return out


def run_box(args, geometry, rng) -> dict:
    """The box with regions of measured MERL materials: simulate, measure, fit, held-out MAE, per
    region too (no analytic truth: the models are judged on the held-out frames only)."""
    mat = merl_box_material()
    box = box_mesh()
    truth_tracer = MeshTracer(box.vertices, box.faces, box.vertex_normals)
    tracer, points = prepare(box, args.box_spacing)
    t0 = time.time()
    groups, merged, raw = simulate(geometry, truth_tracer, mat, args.positions, rng)
    t_sim = time.time() - t0
    meas = measure(geometry, tracer, points, groups, merged)
    fits = fit_measurements(meas, len(points))
    t_fit = time.time() - t0 - t_sim
    frames = [(0, g.angle_deg, g.light, 255, t, img)
              for g, imgs in zip(groups, raw) if is_held_out(g.position, g.light, geometry)
              for t, img in zip(EXPOSURES, imgs)]
    reflectances = {m: fitted_reflectance(fits, m, points) for m in MODELS}
    pca = {}
    if args.basis is not None:
        # abs's data-driven model per point (abs.lightstage.pcafit), beside the analytic three.
        from abs.brdf.basis import BRDFBasis
        from abs.lightstage.pcafit import fit_pca_points, pca_reflectance

        basis = BRDFBasis.load(args.basis)
        t1 = time.time()
        pfits = fit_pca_points(basis, meas, len(points))
        reflectances["brdf_pca"] = pca_reflectance(basis, pfits, points)
        pca = {"basis": {"file": args.basis.name, "components": basis.n_components,
                         "training_materials": None if basis.materials is None else len(basis.materials),
                         "holds_out_the_box_materials": bool(basis.materials is not None and not set(
                             BOX_MATERIALS) & set(map(str, basis.materials)))},
               "points_fitted": int((pfits.count > 0).sum()), "seconds": round(time.time() - t1, 1)}
    result = evaluate_held_out(geometry, tracer, frames, reflectances)
    # Per region: the same Eq. 4.1 over the held-out pixels whose ray lands in that region.
    per_region = {name: {m: round(v, 6) for m, v in evaluate_held_out(
        geometry, tracer, frames, reflectances, select=lambda p, r=r: box_region(p) == r).items()}
        for r, name in enumerate(BOX_MATERIALS)}
    fitted = fits.count > 0
    return {"materials_by_region": dict(zip(("top", "upper sides", "lower sides"), BOX_MATERIALS)),
            "mae_eq_4_1_held_out": {m: round(v, 6) for m, v in result.items()},
            "mae_eq_4_1_held_out_by_region": per_region,
            "converged_fraction": fits.converged_fraction(), "brdf_pca": pca,
            "points": len(points), "points_fitted": int(fitted.sum()),
            "measurements": len(meas), "held_out_frames": len(frames),
            "median_measurements_per_fitted_point": float(np.median(fits.count[fitted])),
            "cook_torrance_beats_lambert": bool(result["cook_torrance"] < result["lambert"]),
            "seconds": {"simulate": round(t_sim, 1), "measure_and_fit": round(t_fit, 1)}}


def run_calibration(args, geometry, save=None) -> dict:
    """Calibrate a perturbed rig from simulated frames; measure/fit with and without calibration.

    ``save(result)`` is called after the calibration and after each fit (partial results)."""
    from abs.lightstage.calibration import CalibrationData, calibrate
    from abs.lightstage.calsim import (BALL_CENTER, BALL_RADIUS, BOARD_ALBEDO, BOARD_CORNERS, ball_frame,
                                       board_frame, perturbed_rig)
    from abs.lightstage.greyboard import LedFrame, board_tracer

    rng = np.random.default_rng(2027)
    truth = perturbed_rig(geometry, rng)
    t0 = time.time()
    angles = np.arange(0.0, 360.0, 30.0)
    ball = [LedFrame(a, k, 255, 0.01, ball_frame(truth, a, k, rng)) for a in angles for k in sorted(geometry.leds)]
    tracer = board_tracer(BOARD_CORNERS)
    board = [LedFrame(0.0, k, 255, 0.02, board_frame(truth, tracer, 0.0, k, 0.02, rng))
             for k in sorted(geometry.leds)]
    t_sim = time.time() - t0
    calibrated, report = calibrate(geometry, CalibrationData(BALL_CENTER, BALL_RADIUS, BOARD_CORNERS,
                                                             BOARD_ALBEDO, ball, board))
    t_cal = time.time() - t0 - t_sim
    names = sorted(geometry.leds)

    def position_mm(g):
        e = 1e3 * np.array([np.linalg.norm(g.leds[k].position - truth.leds[k].position) for k in names])
        return {"median": round(float(np.median(e)), 3), "rms": round(float(np.sqrt(np.mean(e ** 2))), 3),
                "max": round(float(e.max()), 3)}

    def intensity_rel(g):
        e = np.abs(np.array([g.leds[k].intensity / truth.leds[k].intensity - 1.0 for k in names]))
        return {"median": round(float(np.median(e)), 5), "max": round(float(e.max()), 5)}

    out = {"truth": {"position_sigma_mm": 8.0, "intensity_spread": 0.25,
                     "attenuation_exponent": truth.attenuation.exponent},
           "geometry_file": {"attenuation_exponent": geometry.attenuation.exponent},
           "ball": {"center_m": BALL_CENTER.tolist(), "radius_m": BALL_RADIUS, "stops": len(angles),
                    "frame_size": f"{8 * geometry.cameras[0].width}x{8 * geometry.cameras[0].height}"},
           "board": {"corners_m": BOARD_CORNERS.tolist(), "albedo": BOARD_ALBEDO.tolist(),
                     "frame_size": f"{geometry.cameras[0].width}x{geometry.cameras[0].height}"},
           "led_position_error_mm": {"geometry_file": position_mm(geometry), "calibrated": position_mm(calibrated)},
           "led_intensity_relative_error": {"geometry_file": intensity_rel(geometry),
                                            "calibrated": intensity_rel(calibrated)},
           "attenuation_exponent": {"truth": truth.attenuation.exponent, "geometry_file": geometry.attenuation.exponent,
                                    "calibrated": round(calibrated.attenuation.exponent, 4)},
           "attenuation_measured_up_to_deg": report["attenuation"]["measured_up_to_deg"],
           "report": report, "seconds": {"simulate": round(t_sim, 1), "calibrate": round(t_cal, 1)},
           "object": args.calibration_object, "fits": {}}
    if save:
        save(out)
    for label, g in (("geometry_file", geometry), ("calibrated", calibrated), ("truth", truth)):
        print(f"calibration: {args.calibration_object} measured with the {label} geometry ...", flush=True)
        r = run_object(args.calibration_object, args, g, truth)
        out["fits"][label] = {k: r[k] for k in ("mae_eq_4_1_held_out", "converged_fraction", "points_fitted",
                                                 "recovered_parameters", "seconds")}
        print(json.dumps(r["mae_eq_4_1_held_out"]), flush=True)
        if save:
            save(out)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--positions", type=int, default=12, help="turntable stops (thesis: 40)")
    parser.add_argument("--size", default="64x48", help="image size WxH")
    parser.add_argument("--spacing", type=float, default=0.01, help="surface point spacing, metres")
    parser.add_argument("--box-spacing", type=float, default=0.03,
                        help="surface point spacing on the MERL box, metres (0.03: 4x4 points a face)")
    parser.add_argument("--basis", type=Path, default=None,
                        help="a brdf_pca basis (abs brdf build-basis): also fit it per point on the MERL box")
    parser.add_argument("--objects", default="lambert_textured,blinn_phong_specular,cook_torrance_specular,merl_box",
                        help="objects to run; the results file keeps the entries of the others")
    parser.add_argument("--out", type=Path, default=None,
                        help=f"results file (default {RESULTS.name}, {CALIBRATION_RESULTS.name} with --calibration)")
    parser.add_argument("--calibration", action="store_true",
                        help="run the light-calibration benchmark instead (module docstring)")
    parser.add_argument("--calibration-object", default="blinn_phong_specular")
    args = parser.parse_args()
    width, height = (int(x) for x in args.size.split("x"))
    geometry = dome(width, height)
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).resolve().parent).stdout.strip()
    if args.calibration:
        out = args.out or CALIBRATION_RESULTS
        settings = {"commit": commit, "settings": {"positions": args.positions, "size": args.size,
                                                  "spacing_m": args.spacing, "leds": len(geometry.leds)}}
        out.parent.mkdir(parents=True, exist_ok=True)

        def save(part):
            out.write_text(json.dumps({**settings, **part}, indent=1) + "\n")

        run_calibration(args, geometry, save)
        print(f"wrote {out}")
        return
    results = {"settings": {"positions": args.positions, "size": args.size, "leds": len(geometry.leds),
                            "exposures_s": EXPOSURES, "spacing_m": args.spacing,
                            "measured_mesh": "icosphere level 3 (1280 triangles)",
                            "truth_mesh": "icosphere level 5 (20480 triangles)",
                            "noise": "Gaussian, sigma 0.003 + 0.01 x value, then clipped at 1",
                            "held_out": "light groups with (position + LED index) % 5 == 0"},
               "thesis_table_4_1": THESIS_TABLE_4_1, "objects": {}}
    out = args.out or RESULTS
    if out.exists():
        # Objects not run now keep their earlier entries (each entry names its commit where known).
        results["objects"] = json.loads(out.read_text()).get("objects", {})
    for name in args.objects.split(","):
        print(f"{name} ...", flush=True)
        results["objects"][name] = {"commit": commit, "positions": args.positions,
                                    **run_object(name, args, geometry)}
        r = results["objects"][name]
        print(json.dumps({k: r[k] for k in ("mae_eq_4_1_held_out", "converged_fraction", "seconds")}),
              flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
