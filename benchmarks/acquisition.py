"""Acquisition (issue 24): calibration, HDR merging and capture building on real and simulated data.

Parts (each resumable: a part already in the JSON is skipped unless ``--force``):

- ``real_stereo``: ``../shared/data/stereo_chessboard_640x512`` (25 real stereo pairs of a 9x6
  chessboard). Left and right intrinsics on all 25 views, stereo on the first 20 pairs, epipolar
  error of the 5 held-out pairs, and the difference from the dataset's own calibration
  (``reference_*.yml``): K, distortion coefficients, the whole intrinsic model's pixel-position
  difference over the image, baseline and rotation.
- ``real_hdr``: ``../shared/data/colorchecker_bandpass_llanos`` (a ColorChecker captured raw at 7
  exposure times under 7 band-pass filters, dark frames, patch labels). Per band: the merged value
  of each patch, the relative spread of its per-exposure rate estimates, and its linearity in
  exposure time (log-log slope; worst deviation from ``merged * t``).
- ``synthetic_calibration``: a checkerboard rendered with Mitsuba at the poses of
  abs.acquisition.synthetic.board_views (up to 18) through a pinhole, then resampled through a
  known K (fx != fy, off-centre principal point) and Brown-Conrady distortion at 3x supersampling,
  area-averaged, blurred, noised and quantised to 8 bits. Error of K (target < 0.5 %) and of the
  distortion's pixel positions over the image (target < 0.1 px where boards were seen).
- ``synthetic_hdr``: an HDR scene (a Poly Haven environment at 128x64, 4 decades) through a
  simulated 12-bit Bayer sensor (Poisson shot noise, read noise, black level, clipping, noisy
  dark frames), 11 exposures one stop apart from 1 ms: the merged mosaic against the linear truth in units of its expected
  noise, the demosaiced merge (written as 16-bit TIFFs, read by ``abs capture build``'s loader)
  against the bilinearly demosaiced truth, and an 8-bit gamma-response (JPEG-like) bracket merged
  with Debevec's recovered response.
- ``end_to_end``: the default scene (scenes/default/scene.toml) seen by 3 cameras (128x96, one
  holdout) with lens distortion; raw RGGB brackets (7 exposures) rendered through the distorted
  camera, ``abs capture build`` with dark frames, then ``abs.fit`` of ``environment.scale`` and
  ``glass.absorption``, against the same fit on an ``abs simulate`` capture of the same views.
- ``end_to_end_superpixel``: ``end_to_end``'s raw brackets (the same data, regenerated) built
  with ``demosaic = "superpixel"`` (a 64x48 capture) and fitted with the same settings; also
  refits the bilinear build at downsample 2 to check that the part reproduces ``end_to_end``.
- ``end_to_end_replicates``: ``end_to_end`` and ``end_to_end_superpixel``'s fits repeated with
  3 other noise seeds (sensor and ``abs simulate``): run-to-run spread of every variant.

Writes ``benchmarks/results/acquisition.json`` and ``benchmarks/results/acquisition.md``.

    PYTHONPATH=. python benchmarks/acquisition.py [--parts real_stereo,...] [--force]
"""

from __future__ import annotations

import argparse
import json
import platform
import re
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from abs.acquisition.board import Board
from abs.acquisition.detection import detect_in_files
from abs.acquisition.hdr import merge_brackets
from abs.acquisition.intrinsics import calibrate_intrinsics, coverage_map
from abs.acquisition.raw import read_raw
from abs.acquisition.stereo import calibrate_stereo, epipolar_errors_px
from abs.acquisition.synthetic import board_views
from abs.io.shared_data import shared_data_dir

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "acquisition.json"
BOARD = Board("checkerboard", 9, 6, 0.025)
# The seed's bracket: 11 exposures one stop apart from 1 ms (1 .. 1024 ms; the seed's "1 to
# 2048 ms" would be 12 exposures).
T_BRACKET = 0.001 * 2.0 ** np.arange(11)


def _stats(v) -> dict:
    v = np.asarray(v, np.float64)
    return {"median": float(np.median(v)), "mean": float(v.mean()), "max": float(v.max())}


# ---------------------------------------------------------------------------------------------
# Distortion applied to pinhole renders
# ---------------------------------------------------------------------------------------------

def _distortion_grid(K: np.ndarray, dist: np.ndarray, width: int, height: int, n: int):
    """Normalised pinhole coordinates (x/z, y/z) of the centres of an n-times finer grid of the
    distorted image ``(H*n, W*n, 2)``, and the symmetric half-extents they reach."""
    xs = (np.arange(width * n) - (n - 1) / 2) / n
    ys = (np.arange(height * n) - (n - 1) / 2) / n
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(grid, K, dist, criteria=crit).reshape(height * n, width * n, 2)
    return rays, np.abs(rays[..., 0]).max(), np.abs(rays[..., 1]).max()


def render_pinhole_size(K, dist, width, height, n):
    """Square-pixel pinhole render (focal, width, height) that covers the distorted view."""
    _, ex, ey = _distortion_grid(K, dist, width, height, n)
    f = n * float(K[0, 0])
    return f, 2 * int(np.ceil(f * ex)) + 6, 2 * int(np.ceil(f * ey)) + 6


def distort_render(render: np.ndarray, f_r: float, K, dist, width, height, n) -> np.ndarray:
    """Resample a centred pinhole render (focal ``f_r``, principal point at its centre) into the
    image of camera ``K``, ``dist`` (bilinear at n-times supersampling, then area-averaged)."""
    rays, _, _ = _distortion_grid(K, dist, width, height, n)
    hr, wr = render.shape[:2]
    mx = (f_r * rays[..., 0] + (wr - 1) / 2).astype(np.float32)
    my = (f_r * rays[..., 1] + (hr - 1) / 2).astype(np.float32)
    fine = cv2.remap(np.asarray(render, np.float32), mx, my, cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    return cv2.resize(fine, (width, height), interpolation=cv2.INTER_AREA)


# ---------------------------------------------------------------------------------------------
# Real stereo pairs
# ---------------------------------------------------------------------------------------------

def _model_difference_px(K_a, d_a, K_b, d_b, width, height, step=4) -> dict:
    """Pixel-position difference of two intrinsic models over the image: each pixel's ray under
    model a, projected by model b."""
    grid = np.stack(np.meshgrid(np.arange(0, width, step, dtype=np.float64),
                                np.arange(0, height, step, dtype=np.float64)), -1).reshape(-1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(grid.reshape(-1, 1, 2), K_a, d_a, criteria=crit).reshape(-1, 2)
    pts = np.concatenate([rays, np.ones((len(rays), 1))], 1)
    proj, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K_b, d_b)
    err = np.linalg.norm(proj.reshape(-1, 2) - grid, axis=1)
    return {"median_px": float(np.median(err)), "p95_px": float(np.percentile(err, 95)),
            "max_px": float(err.max())}


def part_real_stereo() -> dict:
    folder = shared_data_dir() / "stereo_chessboard_640x512"
    if not folder.is_dir():
        return {"skipped": f"shared data absent: {folder}"}
    t0 = time.perf_counter()
    left = detect_in_files(sorted(folder.glob("left*.jpg")), BOARD)
    right = detect_in_files(sorted(folder.glob("right*.jpg")), BOARD)
    obj = BOARD.object_points()
    w, h = left.width, left.height
    cams = {"left": calibrate_intrinsics(left.corners, obj, w, h),
            "right": calibrate_intrinsics(right.corners, obj, w, h)}
    ref = cv2.FileStorage(str(folder / "reference_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    ref_ext = cv2.FileStorage(str(folder / "reference_extrinsics.yml"), cv2.FILE_STORAGE_READ)
    out: dict = {"images_per_camera": len(left.paths), "size": [w, h],
                 "board": "checkerboard 9x6 inner corners, 25 mm assumed (not stated)",
                 "found": {"left": len(left.found), "right": len(right.found)}}
    for (name, c), key in zip(cams.items(), ("1", "2")):
        M, D = ref.getNode(f"M{key}").mat(), ref.getNode(f"D{key}").mat().ravel()
        out[name] = {
            "rms_px": c.rms_px, "view_rms_px": _stats(c.view_rms_px), "outliers": list(c.outliers),
            "coverage": c.coverage, "K": c.K.tolist(), "distortion": c.dist.tolist(),
            "std": c.std,
            "reference": {"K": M.tolist(), "distortion": D.tolist(),
                          "model": "rational (k1,k2,k3,k6), fx = fy, no tangential terms"},
            "difference": {"fx_rel": float(c.K[0, 0] / M[0, 0] - 1),
                           "fy_rel": float(c.K[1, 1] / M[1, 1] - 1),
                           "cx_px": float(c.K[0, 2] - M[0, 2]), "cy_px": float(c.K[1, 2] - M[1, 2]),
                           "model_pixel_position": _model_difference_px(M, D, c.K, c.dist, w, h)},
        }
    train, held = list(range(20)), list(range(20, 25))
    cl, cr = cams["left"], cams["right"]
    st = calibrate_stereo([left.corners[i] for i in train], [right.corners[i] for i in train], obj,
                          cl.K, cl.dist, cr.K, cr.dist, w, h)
    errs = np.concatenate([epipolar_errors_px(left.corners[i], right.corners[i], st.F, cl.K,
                                              cl.dist, cr.K, cr.dist) for i in held])
    errs_train = np.concatenate([epipolar_errors_px(left.corners[i], right.corners[i], st.F, cl.K,
                                                    cl.dist, cr.K, cr.dist) for i in train])
    R_ref, T_ref = ref_ext.getNode("R").mat(), ref_ext.getNode("T").mat().ravel()
    angle = float(np.degrees(np.linalg.norm(cv2.Rodrigues(st.R @ R_ref.T)[0])))
    cosang = float(st.T @ T_ref / (np.linalg.norm(st.T) * np.linalg.norm(T_ref)))
    out["stereo"] = {
        "train_pairs": len(train), "heldout_pairs": len(held), "rms_px": st.rms_px,
        "heldout_epipolar_px": {"rms": float(np.sqrt(np.mean(errs ** 2))), "max": float(errs.max())},
        "train_epipolar_px": {"rms": float(np.sqrt(np.mean(errs_train ** 2)))},
        "R": st.R.tolist(), "T_m": st.T.tolist(),
        "baseline_squares": float(np.linalg.norm(st.T) / BOARD.square_m),
        "rotation_deg": float(np.degrees(np.linalg.norm(cv2.Rodrigues(st.R)[0]))),
        "reference": {"R": R_ref.tolist(), "T": T_ref.tolist(),
                      "baseline": float(np.linalg.norm(T_ref)),
                      "rotation_deg": float(np.degrees(np.linalg.norm(cv2.Rodrigues(R_ref)[0])))},
        "difference": {"rotation_deg": angle,
                       "T_direction_deg": float(np.degrees(np.arccos(np.clip(cosang, -1, 1)))),
                       "reference_units_per_square": float(np.linalg.norm(T_ref)
                                                           / (np.linalg.norm(st.T) / BOARD.square_m))},
    }
    out["seconds"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------------------------
# Real raw stacks
# ---------------------------------------------------------------------------------------------

def part_real_hdr() -> dict:
    root = shared_data_dir() / "colorchecker_bandpass_llanos"
    if not root.is_dir():
        return {"skipped": f"shared data absent: {root}"}
    t0 = time.perf_counter()
    folder = root / "captured_images"
    labels = cv2.imread(str(root / "colorChecker_labels" / "d2_colorChecker30cm_550nm_labels.png"),
                        cv2.IMREAD_UNCHANGED)

    def ms(path: Path) -> int:
        return int(re.search(r"_(\d+)ms_", path.name).group(1))

    files = sorted((folder / "images_filtered_light" / "color_checker").glob("*.tif"))
    bands = sorted({re.search(r"_(\d+nm)_", f.name).group(1) for f in files})
    dark_cache: dict[int, np.ndarray] = {}

    def dark(t_ms: int) -> np.ndarray:
        if t_ms not in dark_cache:
            dark_cache[t_ms] = np.mean([read_raw(d).mosaic for d in sorted(
                (folder / "dark_frames").glob(f"d2_dark_{t_ms}ms_*.tif"))], axis=0)
        return dark_cache[t_ms]

    out: dict = {"labels": "d2_colorChecker30cm_550nm_labels.png (same camera pose for all bands)",
                 "bands": {}}
    all_spreads, all_dev, all_slopes = [], [], []
    for band in bands:
        stack = sorted((f for f in files if f"_{band}_" in f.name), key=ms)
        frames = [read_raw(f) for f in stack]
        t = np.array([ms(f) for f in stack]) / 1000.0
        darks = [dark(ms(f)) for f in stack]
        merged = merge_brackets([f.mosaic for f in frames], t, frames[0].white_level, darks)
        patches = {}
        for patch in range(1, 25):
            sel = labels == patch
            usable = [i for i in range(len(t)) if frames[i].mosaic[sel].max()
                      < 0.95 * frames[i].white_level
                      and (frames[i].mosaic[sel] - darks[i][sel]).mean() > 10]
            value = float(merged.radiance[sel].mean())
            entry = {"merged_dn_per_s": value, "exposures_used": len(usable)}
            if len(usable) >= 2:
                means = np.array([(frames[i].mosaic[sel] - darks[i][sel]).mean() for i in usable])
                rates = means / t[usable]
                dev = np.abs(means / (value * t[usable]) - 1)
                slope = float(np.polyfit(np.log(t[usable]), np.log(means), 1)[0])
                entry.update(relative_spread=float(rates.std() / rates.mean()),
                             max_deviation_from_linear=float(dev.max()), loglog_slope=slope)
                all_spreads.append(entry["relative_spread"])
                all_dev.append(entry["max_deviation_from_linear"])
                all_slopes.append(slope)
            patches[str(patch)] = entry
        good = [p for p in patches.values() if "relative_spread" in p]
        out["bands"][band] = {
            "exposures_ms": (t * 1000).round().astype(int).tolist(),
            "white_level": frames[0].white_level, "patches_measured": len(good),
            "relative_spread": _stats([p["relative_spread"] for p in good]) if good else None,
            "max_deviation_from_linear": _stats([p["max_deviation_from_linear"] for p in good])
            if good else None,
            "loglog_slope": _stats([p["loglog_slope"] for p in good]) if good else None,
            "patches": patches}
    out["all_bands"] = {"patches_measured": len(all_spreads),
                        "relative_spread": _stats(all_spreads),
                        "max_deviation_from_linear": _stats(all_dev),
                        "loglog_slope": {"min": float(np.min(all_slopes)),
                                         "median": float(np.median(all_slopes)),
                                         "max": float(np.max(all_slopes))}}
    out["seconds"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------------------------
# Synthetic calibration: a checkerboard rendered with Mitsuba
# ---------------------------------------------------------------------------------------------

K_SYN = np.array([[300.0, 0, 161.3], [0, 302.0, 118.7], [0, 0, 1]])
DIST_SYN = np.array([-0.21, 0.09, 0.001, -0.0015, 0.0])
SIZE_SYN = (320, 240)


def _board_texture(px: int = 16) -> np.ndarray:
    """12x9 squares: a 10x7-square chessboard (9x6 inner corners) inside a one-square white
    margin; black 0.04, white 0.85 (linear)."""
    tex = np.full((9 * px, 12 * px), 0.85, np.float32)
    for r in range(7):
        for c in range(10):
            if (r + c) % 2 == 0:
                tex[(r + 1) * px:(r + 2) * px, (c + 1) * px:(c + 2) * px] = 0.04
    return tex


def render_board(R: np.ndarray, t: np.ndarray, f_r: float, w_r: int, h_r: int, spp: int) -> np.ndarray:
    """Mitsuba render (grey, linear) of the board at pose (R, t) (board -> OpenCV camera) through
    a square-pixel pinhole of focal ``f_r`` with the principal point at the image centre."""
    from abs.render.variant import set_variant

    set_variant()
    import mitsuba as mi

    s = BOARD.square_m
    tex = _board_texture()
    # Board coordinates: inner corner (i, j) at (i s, j s, 0). The rectangle spans [-1, 1]^2 with
    # uv (0, 0) at (-1, -1) and the texture's row 0 at v = 0: centre it on (4 s, 2.5 s).
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    to_world = (mi.ScalarTransform4f(M.tolist()) @ mi.ScalarTransform4f().translate([4 * s, 2.5 * s, 0])
                @ mi.ScalarTransform4f().scale([6 * s, 4.5 * s, 1]))
    bitmap = mi.Bitmap(np.repeat(tex[..., None], 3, -1))
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "board": {"type": "rectangle", "to_world": to_world, "flip_normals": True,
                  "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": bitmap,
                                                           "filter_type": "nearest", "raw": True}}},
        # The OpenCV camera frame (x right, y down, z forward) is Mitsuba's world frame.
        "sensor": {"type": "perspective", "fov_axis": "x",
                   "fov": float(np.degrees(2 * np.arctan(w_r / 2 / f_r))),
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1],
                                                              up=[0, -1, 0]),
                   "film": {"type": "hdrfilm", "width": w_r, "height": h_r, "pixel_format": "rgb",
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}}})
    return np.asarray(mi.render(scene, seed=1), np.float32).mean(axis=-1)


def part_synthetic_calibration(n: int = 3, spp: int = 4, blur_px: float = 0.5,
                               noise: float = 0.01) -> dict:
    t0 = time.perf_counter()
    rng = np.random.default_rng(5)
    W, H = SIZE_SYN
    f_r, w_r, h_r = render_pinhole_size(K_SYN, DIST_SYN, W, H, n)
    poses = board_views(BOARD, K_SYN, DIST_SYN, W, H)
    obj = BOARD.object_points().astype(np.float64)
    with tempfile.TemporaryDirectory() as tmp:
        paths, truth = [], []
        for k, view in enumerate(poses):
            pin = render_board(view.R, view.t, f_r, w_r, h_r, spp)
            img = distort_render(pin, f_r, K_SYN, DIST_SYN, W, H, n)
            img = cv2.GaussianBlur(img, (0, 0), blur_px)
            img = img + rng.normal(0, noise, img.shape)
            path = Path(tmp) / f"board{k:02d}.png"
            cv2.imwrite(str(path), np.clip(np.round(img * 255), 0, 255).astype(np.uint8))
            paths.append(path)
            truth.append(view.corners)
        det = detect_in_files(paths, BOARD)
    found = det.found
    corner_err = []
    for i in found:
        c = det.corners[i]
        e = min(np.linalg.norm(c - truth[i], axis=1).max(), np.linalg.norm(c[::-1] - truth[i], axis=1).max())
        corner_err.append(np.linalg.norm((c if np.linalg.norm(c - truth[i], axis=1).max() == e
                                          else c[::-1]) - truth[i], axis=1))
    corner_err = np.concatenate(corner_err)
    calib = calibrate_intrinsics([det.corners[i] for i in found], obj, W, H)
    rel = np.array([calib.K[0, 0], calib.K[1, 1], calib.K[0, 2], calib.K[1, 2]]) \
        / K_SYN[[0, 1, 0, 1], [0, 1, 2, 2]] - 1
    grid = np.stack(np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64)),
                    -1).reshape(-1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(grid.reshape(-1, 1, 2), K_SYN, DIST_SYN, criteria=crit).reshape(-1, 2)
    pts = np.concatenate([rays, np.ones((len(rays), 1))], 1)
    ours, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), calib.K, calib.dist)
    err = np.linalg.norm(ours.reshape(-1, 2) - grid, axis=1)
    # The distortion alone: the same rays through the recovered distortion with the TRUE K.
    ours_d, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K_SYN, calib.dist)
    err_d = np.linalg.norm(ours_d.reshape(-1, 2) - grid, axis=1)
    seen = coverage_map([det.corners[i] for i in found], W, H).ravel() > 0
    return {
        "renderer": "Mitsuba 3 (direct integrator, emissive textured rectangle), pinhole at "
                    f"{n}x then distorted by resampling and area-averaged",
        "size": [W, H], "K_true": K_SYN.tolist(), "distortion_true": DIST_SYN.tolist(),
        "poses": len(poses), "found": len(found), "spp": spp, "blur_sigma_px": blur_px,
        "noise_sd": noise, "levels": "black 0.04, white 0.85 of 8-bit full scale",
        "corner_error_px": {"rms": float(np.sqrt(np.mean(corner_err ** 2))),
                            "max": float(corner_err.max())},
        "rms_px": calib.rms_px, "K": calib.K.tolist(), "distortion": calib.dist.tolist(),
        "K_error_rel": {"fx": float(rel[0]), "fy": float(rel[1]), "cx": float(rel[2]),
                        "cy": float(rel[3]), "max_abs": float(np.abs(rel).max())},
        "K_std_rel": {k: calib.std[k] / v for k, v in
                      (("fx", K_SYN[0, 0]), ("fy", K_SYN[1, 1]), ("cx", K_SYN[0, 2]), ("cy", K_SYN[1, 2]))},
        "pixel_position_error_px": {
            "model_seen": {"median": float(np.median(err[seen])), "max": float(err[seen].max())},
            "model_whole_image": {"median": float(np.median(err)), "max": float(err.max())},
            "distortion_only_seen": {"max": float(err_d[seen].max())},
            "distortion_only_whole_image": {"max": float(err_d.max())}},
        "coverage": float(seen.mean()),
        "targets": {"K_rel": 0.005, "pixel_position_px": 0.1},
        "seconds": time.perf_counter() - t0,
    }


# ---------------------------------------------------------------------------------------------
# Synthetic HDR: an environment map through a simulated sensor
# ---------------------------------------------------------------------------------------------

def _hdr_scene(width=128, height=64) -> np.ndarray:
    folder = shared_data_dir() / "polyhaven_hdri_1k"
    path = folder / "royal_esplanade_1k.hdr"
    if path.is_file():
        bgr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        rgb = cv2.resize(bgr[..., ::-1].astype(np.float32), (width, height),
                         interpolation=cv2.INTER_AREA).astype(np.float64)
        return np.maximum(rgb, 1e-4 * rgb.max())
    rng = np.random.default_rng(7)  # fallback: a log-uniform field over 4.6 decades
    return np.exp(rng.uniform(np.log(1e-3), np.log(40.0), (height, width, 3)))


def part_synthetic_hdr() -> dict:
    from abs.acquisition.build import load_frame
    from abs.acquisition.demosaic import cfa_masks, demosaic_bilinear
    from abs.acquisition.response import merge_ldr, recover_response

    t0 = time.perf_counter()
    rng = np.random.default_rng(11)
    scene = _hdr_scene()
    H, W = scene.shape[:2]
    white, black, read = 4095.0, 64.0, 2.0
    # Exposure scale: the brightest pixel reaches 80 % of full scale in the 1 ms frame.
    gain = 0.8 * (white - black) / (scene.max() * T_BRACKET[0])
    L_rgb = scene * gain  # DN/s
    masks = cfa_masks((H, W), "RGGB")
    L = np.sum(L_rgb * masks, axis=-1)
    frames, darks = [], []
    for t in T_BRACKET:
        raw = rng.poisson(L * t) + black + rng.normal(0, read, L.shape)
        frames.append(np.clip(np.round(raw), 0, white))
        darks.append(np.mean([np.round(black + rng.normal(0, read, L.shape)) for _ in range(4)], 0))
    merged = merge_brackets(frames, T_BRACKET, white, darks)
    wgt = merged.weight
    n_used = merged.used.sum(axis=0)
    var = (L * wgt + n_used * (read ** 2 + read ** 2 / 4 + 1 / 12)) / np.maximum(wgt, 1e-12) ** 2
    ok = wgt > 0
    z = (merged.radiance[ok] - L[ok]) / np.sqrt(var[ok])
    rel = merged.radiance[ok] / L[ok] - 1
    out: dict = {
        "scene": "royal_esplanade_1k.hdr (Poly Haven), 128x64, RGGB mosaic",
        "dynamic_range": float(L.max() / L.min()), "exposures_ms": (T_BRACKET * 1000).tolist(),
        "sensor": {"white_level": white, "black_level": black, "read_noise_dn": read,
                   "shot_noise": "Poisson", "dark_frames": "4 noisy frames averaged per exposure"},
        "mosaic": {"normalised_error_rms": float(np.sqrt(np.mean(z ** 2))),
                   "normalised_error_mean": float(np.mean(z)),
                   "relative_error_median_abs": float(np.median(np.abs(rel))),
                   "relative_bias": float(np.mean(rel)),
                   "saturated_everywhere": int(merged.saturated_everywhere.sum()),
                   "no_usable_frame": int((~ok).sum())},
    }
    # Through the capture builder's loader: 16-bit TIFF mosaics, bilinear demosaic, clipped-site
    # masks. The truth is the bilinearly demosaiced truth mosaic (demosaicing is linear).
    with tempfile.TemporaryDirectory() as tmp:
        loaded, sats = [], []
        for i, f in enumerate(frames):
            path = Path(tmp) / f"f{i}.tif"
            cv2.imwrite(str(path), f.astype(np.uint16))
            rgb, sat = load_frame(path, "RGGB", white_level=white)
            loaded.append(rgb)
            sats.append(sat)
        dark_rgb = [demosaic_bilinear(d, "RGGB") for d in darks]
    m_rgb = merge_brackets(loaded, T_BRACKET, np.inf, dark_rgb, saturated=sats)
    truth_rgb = demosaic_bilinear(L, "RGGB").astype(np.float64)
    inner = (slice(2, -2), slice(2, -2))
    r = m_rgb.radiance[inner] / truth_rgb[inner] - 1
    out["demosaiced"] = {"relative_error_median_abs": float(np.median(np.abs(r))),
                         "relative_error_p95_abs": float(np.percentile(np.abs(r), 95)),
                         "relative_bias": float(np.mean(r)),
                         "note": "16-bit TIFFs read by abs.acquisition.build.load_frame"}
    # JPEG-like: 8-bit frames of a gamma response (in-camera demosaiced RGB), 11 exposures.
    gamma = 1 / 2.2
    k = 0.8 / (scene.max() * T_BRACKET[0])
    ldr = []
    for t in T_BRACKET:
        x = np.clip(scene * k * t * (1 + rng.normal(0, 0.01, scene.shape)), 0, 1)
        ldr.append(np.clip(np.round(255 * x ** gamma), 0, 255).astype(np.uint8))
    response = recover_response(ldr, T_BRACKET, samples=300)
    m = merge_ldr(ldr, T_BRACKET, response).astype(np.float64)
    seen = (scene * k * T_BRACKET[0] < 0.9) & (scene * k * T_BRACKET[-1] > 0.02)  # unclipped somewhere
    le = np.log(np.maximum(m, 1e-30) / scene)[seen]
    le -= np.median(le)
    codes = np.arange(1, 255)
    true_inverse = ((codes / 255.0) ** (1 / gamma))[:, None]  # code -> relative exposure
    ratio = np.log(response[codes] / true_inverse)
    ratio -= np.median(ratio, axis=0)
    out["jpeg_like"] = {"response": "x^(1/2.2), 1 % multiplicative noise, 8-bit",
                        "log_error_median_abs": float(np.median(np.abs(le))),
                        "log_error_p95_abs": float(np.percentile(np.abs(le), 95)),
                        "response_log_error_median_abs": float(np.median(np.abs(ratio)))}
    out["seconds"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------------------------------------
# End to end: raw brackets of the default scene -> capture build -> fit
# ---------------------------------------------------------------------------------------------

E2E = {"width": 128, "height": 96, "views": 3, "truth_spp": 1024, "fit_spp": 32,
       "max_iterations": 12, "refinement_steps": 6, "supersample": 2,
       "distortion": [-0.12, 0.02, 0.0005, -0.0005, 0.0], "gain_dn_per_s": 2.0e5,
       "exposures_s": (0.001 * 4.0 ** np.arange(7)).tolist(), "start_scale_factor": 1.3,
       "start_absorption": [2.5, 2.5, 2.5], "downsamples": [1, 2]}


def _e2e_raw_brackets(compiled, views, raw: Path, cfg: dict, noise_seed: int = 3,
                      render=None) -> Path:
    """``end_to_end``'s raw RGGB brackets (12-bit TIFFs, dark frame, camera file, build file)
    of ``views`` through the distorted cameras, in ``raw``; the same data on every call with the
    same ``noise_seed`` (the sensor noise's; the renders' seeds are fixed). ``render(compiled,
    camera, spp, seed) -> (H, W, 3)`` replaces abs's renderer for the scene renders (the glass
    benchmark's plain Mitsuba). Returns the folder."""
    from abs.acquisition.camera_file import CameraModel, write_camera_file
    from abs.acquisition.demosaic import cfa_masks
    from abs.render import Camera

    W, H, n = cfg["width"], cfg["height"], cfg["supersample"]
    dist = np.array(cfg["distortion"])
    rng = np.random.default_rng(noise_seed)
    white, black, read, gain = 4095.0, 64.0, 2.0, cfg["gain_dn_per_s"]
    t_exp = np.array(cfg["exposures_s"])
    raw.mkdir()
    cams, build_views = {}, []
    masks = cfa_masks((H, W), "RGGB")
    for i, view in enumerate(views):
        K = np.asarray(view["K"], np.float64)
        f_r, w_r, h_r = render_pinhole_size(K, dist, W, H, n)
        K_r = np.array([[f_r, 0, (w_r - 1) / 2], [0, f_r, (h_r - 1) / 2], [0, 0, 1]])
        cam = Camera(K_r, np.asarray(view["R"]), np.asarray(view["t"]), w_r, h_r)
        spp, seed = cfg["truth_spp"] // (n * n) or 1, cfg.get("truth_seed", 500) + i
        pin = (compiled.render(cam, spp=spp, seed=seed).numpy() if render is None
               else render(compiled, cam, spp, seed))
        rgb = distort_render(pin, f_r, K, dist, W, H, n)
        L = np.sum(np.maximum(rgb, 0) * gain * masks, axis=-1)
        name = f"cam{i}"
        cams[name] = CameraModel(W, H, K, dist, R=np.asarray(view["R"]), t=np.asarray(view["t"]))
        frames = []
        for t in t_exp:
            f = np.clip(np.round(rng.poisson(L * t) + black + rng.normal(0, read, L.shape)), 0, white)
            fname = f"{name}_{int(round(t * 1000)):05d}ms.tif"
            cv2.imwrite(str(raw / fname), f.astype(np.uint16))
            frames.append(fname)
        build_views.append({"name": view["name"], "camera": name, "frames": frames,
                            "exposures_s": t_exp.tolist(), "darks": ["dark.tif"] * len(frames),
                            "holdout": i == cfg["views"] - 1})
    cv2.imwrite(str(raw / "dark.tif"), np.full((H, W), black, np.uint16))
    write_camera_file(raw / "cameras.json", cams)
    (raw / "build.json").write_text(json.dumps({"cameras": "cameras.json", "cfa_pattern": "RGGB",
                                                "white_level": white, "views": build_views}))
    return raw


def _e2e_fit(scene_path: Path, folder: Path, unit: float, ds: int, truth: dict, cfg: dict) -> dict:
    """``end_to_end``'s fit of ``environment.scale`` and ``glass.absorption`` on a capture from
    the common start; ``environment.scale`` divided by ``unit`` (the sensor gain for a built
    capture) before comparison with the truth."""
    from abs.fitting import FitSettings, fit

    t1 = time.perf_counter()
    settings = FitSettings(spp=cfg["fit_spp"], max_iterations=cfg["max_iterations"],
                           refinement_steps=cfg["refinement_steps"], downsample=ds)
    initial = {"environment.scale": [truth["environment.scale"] * unit * cfg["start_scale_factor"]],
               "glass.absorption": cfg["start_absorption"]}
    result = fit(scene_path, folder, settings=settings, initial=initial)
    scale = float(np.ravel(result.values["environment.scale"])[0]) / unit
    absorption = np.ravel(result.values["glass.absorption"])
    stderr = result.vector.split(result.uncertainty.stderr)
    scale_se = float(np.ravel(stderr["environment.scale"])[0]) / unit
    absorption_se = np.ravel(stderr["glass.absorption"])
    true_abs = np.array(truth["glass.absorption"])
    holdout = result.metrics.get("holdout_rmse") or {}
    return {
        "environment_scale": scale, "environment_scale_stderr": scale_se,
        "environment_scale_rel_error": scale / truth["environment.scale"] - 1,
        "glass_absorption": absorption.tolist(),
        "glass_absorption_stderr": absorption_se.tolist(),
        "glass_absorption_error": (absorption - true_abs).tolist(),
        "glass_absorption_z": ((absorption - true_abs) / absorption_se).tolist(),
        "glass_absorption_rel_error": (absorption / true_abs - 1).tolist(),
        "downsample": ds,
        "holdout_rmse_in_scene_units": {k: v / unit for k, v in holdout.items()},
        "seconds": time.perf_counter() - t1}


def _e2e_setup():
    """The end-to-end parts' common start: the default scene (path, loaded, compiled), its
    ``E2E`` views and the true fitted values."""
    from abs import load_scene
    from abs.render import compile_scene
    from abs.simulate import place_cameras

    scene_path = ROOT / "scenes" / "default" / "scene.toml"
    scene = load_scene(scene_path)
    compiled = compile_scene(scene)
    views = place_cameras(compiled, E2E["views"], E2E["width"], E2E["height"])
    truth = {"environment.scale": float(compiled.get("environment.scale")[0]),
             "glass.absorption": compiled.get("glass.absorption").tolist()}
    return scene_path, scene, compiled, views, truth


def part_end_to_end() -> dict:
    from abs.acquisition.build import build_capture
    from abs.simulate import simulate_capture

    t0 = time.perf_counter()
    cfg = E2E
    scene_path, scene, compiled, views, truth = _e2e_setup()
    W, H = cfg["width"], cfg["height"]
    gain = cfg["gain_dn_per_s"]
    out: dict = {"config": {k: v for k, v in cfg.items()}, "truth": truth}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # abs simulate of the same views (pinhole photographs, no distortion) as the reference.
        t1 = time.perf_counter()
        simulate_capture(scene, tmp / "simulated", n_cameras=cfg["views"], width=W, height=H,
                         spp=cfg["truth_spp"], shot_noise=1e-4, read_noise=0.003, seed=2)
        out["simulate_seconds"] = time.perf_counter() - t1
        # Raw brackets through distorted cameras.
        t1 = time.perf_counter()
        raw = _e2e_raw_brackets(compiled, views, tmp / "raw", cfg)
        _, merges = build_capture(raw / "build.json", tmp / "built")
        out["raw_seconds"] = time.perf_counter() - t1
        out["saturated_everywhere"] = int(sum(m.saturated_everywhere.sum() for m in merges.values()))
        # Fits from the same start (environment.scale in the capture's units: 1 for the
        # simulated capture, the sensor gain in DN/s for the built one).
        runs = [(f"{label}{'' if ds == 1 else f'_downsample{ds}'}", folder, unit, ds)
                for ds in cfg["downsamples"]
                for label, folder, unit in (("simulate", tmp / "simulated", 1.0),
                                            ("built_from_raw", tmp / "built", gain))]
        for label, folder, unit, ds in runs:
            out[label] = _e2e_fit(scene_path, folder, unit, ds, truth, cfg)
    out["seconds"] = time.perf_counter() - t0
    return out


def part_end_to_end_superpixel() -> dict:
    """``end_to_end``'s raw brackets (regenerated: the same data) built with
    ``demosaic = "superpixel"`` (64x48 capture, the half-resolution cameras) and fitted at
    downsample 1, with the same settings and start. Also refits the bilinear build at downsample 2
    (``built_from_raw_downsample2``'s fit, the same 64x48 fitted resolution) as a check that the
    data and fit reproduce the ``end_to_end`` part's."""
    from abs.acquisition.build import build_capture

    t0 = time.perf_counter()
    cfg = E2E
    scene_path, _, compiled, views, truth = _e2e_setup()
    out: dict = {"config": "as end_to_end; build demosaic superpixel", "truth": truth}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        raw = _e2e_raw_brackets(compiled, views, tmp / "raw", cfg)
        capture, _ = build_capture(raw / "build.json", tmp / "superpixel", demosaic="superpixel")
        build_capture(raw / "build.json", tmp / "bilinear")
        out["capture_size"] = list(capture.views[0].read_image().shape[1::-1])
        out["cameras_K"] = {v.name: np.asarray(v.K).tolist() for v in capture.views}
        gain = cfg["gain_dn_per_s"]
        out["built_from_raw_superpixel"] = _e2e_fit(scene_path, tmp / "superpixel", gain, 1,
                                                    truth, cfg)
        out["built_from_raw_downsample2_rerun"] = _e2e_fit(scene_path, tmp / "bilinear", gain, 2,
                                                           truth, cfg)
    out["seconds"] = time.perf_counter() - t0
    return out


def _one_run(cfg: dict, runs) -> dict:
    """Fits of ``runs`` (label, capture folder of :func:`_e2e_captures`, unit, downsample) on
    one set of end-to-end captures (simulate seed 2, noise seed 3)."""
    t0 = time.perf_counter()
    scene_path, scene, compiled, views, truth = _e2e_setup()
    out: dict = {"config": {k: v for k, v in cfg.items()}, "truth": truth}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        out["blur_px"] = _e2e_captures(tmp, scene, compiled, views, cfg, simulate_seed=2,
                                       noise_seed=3)
        for label, folder, unit, ds in runs:
            out[label] = _e2e_fit(scene_path, tmp / folder, unit, ds, truth, cfg)
            print(label, np.round(out[label]["glass_absorption_error"], 2),
                  np.round(out[label]["glass_absorption_stderr"], 2),
                  round(out[label]["seconds"]), flush=True)
    out["seconds"] = time.perf_counter() - t0
    return out


def part_end_to_end_blur() -> dict:
    """``end_to_end`` with the capture's processing blur modelled (``blur_px`` in
    ``cameras.json``, written by ``build_capture`` since it measures its demosaicing and
    undistortion's blur; the fit's sensor blurs its renderings alike), in one run beside its
    references: the simulated capture at downsample 1 and 2, the bilinear build at downsample 1
    and 2, the same bilinear build with ``blur_px`` removed (the renderer draws it sharp, as
    before the blur was modelled), and the superpixel build. The same raw brackets (noise seed 3)
    and start as ``end_to_end``, fitted at 128 samples per pixel instead of 32: today's fits of
    absorption and scale reweight one path-length recording per view instead of rendering at
    every step (issue 31), so the fit's samples are the recording's, and at 32 the simulated
    capture's green absorption is not measured (the fit says so: standard error 1e4).
    Measured before builds wrote ``processing``: rerunning it now fits the bilinear and
    superpixel builds through their footprints (``end_to_end_footprint``)."""
    gain = E2E["gain_dn_per_s"]
    return _one_run({**E2E, "fit_spp": 128},
                    (("simulate", "simulated", 1.0, 1), ("simulate_downsample2", "simulated", 1.0, 2),
                     ("built_from_raw", "bilinear", gain, 1),
                     ("built_from_raw_downsample2", "bilinear", gain, 2),
                     ("built_from_raw_unblurred", "unblurred", gain, 1),
                     ("built_from_raw_superpixel", "superpixel", gain, 1)))


def part_end_to_end_footprint() -> dict:
    """``end_to_end_blur``'s comparison with the build's exact processing: captures now carry
    ``processing`` (the sensor's camera, demosaicing and CFA pattern), and fits render the sensor
    sites and apply the build's own weights (:mod:`abs.acquisition.footprint`). In one run: the
    simulated capture, the bilinear build (footprint) at downsample 1 and 2, the same build
    fitted through ``blur_px``'s Gaussian instead (``processing`` removed), and the superpixel
    build (footprint). Raw brackets with noise seed 3, 128 samples per pixel, the same start."""
    gain = E2E["gain_dn_per_s"]
    return _one_run({**E2E, "fit_spp": 128},
                    (("simulate", "simulated", 1.0, 1), ("built_from_raw", "bilinear", gain, 1),
                     ("built_from_raw_gaussian", "gaussian", gain, 1),
                     ("built_from_raw_downsample2", "bilinear", gain, 2),
                     ("built_from_raw_superpixel", "superpixel", gain, 1)))


def part_end_to_end_footprint_replicates() -> dict:
    """``end_to_end_footprint``'s captures with the replicate seeds: the simulated capture, the
    bilinear build through its footprint and through ``blur_px``, the superpixel build."""
    gain = E2E["gain_dn_per_s"]
    return _replicates({**E2E, "fit_spp": 128},
                       (("simulate", "simulated", 1.0, 1), ("built_from_raw", "bilinear", gain, 1),
                        ("built_from_raw_gaussian", "gaussian", gain, 1),
                        ("built_from_raw_superpixel", "superpixel", gain, 1)))


def part_end_to_end_blur_render_seeds() -> dict:
    """``end_to_end_blur``'s bilinear build (blur modelled) and its simulated reference with other
    seeds for the scene renders behind the raw brackets (``end_to_end`` uses 500 + view; every
    other part shares those renders): how much of the built capture's remaining error is that
    one render's Monte-Carlo error. Sensor-noise seed 3, simulate seed 2, 128 spp fits.
    Measured before builds wrote ``processing`` (rerunning it now fits the footprint)."""
    t0 = time.perf_counter()
    out: dict = {"config": "as end_to_end_blur; truth render seeds 700, 900 (+ view)"}
    for truth_seed in (700, 900):
        cfg = {**E2E, "fit_spp": 128, "truth_seed": truth_seed}
        scene_path, scene, compiled, views, truth = _e2e_setup()
        out["truth"] = truth
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            _e2e_captures(tmp, scene, compiled, views, cfg, simulate_seed=2, noise_seed=3)
            fitted = _e2e_fit(scene_path, tmp / "bilinear", cfg["gain_dn_per_s"], 1, truth, cfg)
        out[str(truth_seed)] = fitted
        print(truth_seed, np.round(fitted["glass_absorption_error"], 2), flush=True)
    out["seconds"] = time.perf_counter() - t0
    return out


#: Sensor-noise seeds of ``end_to_end_replicates`` (``end_to_end`` itself uses 3).
E2E_REPLICATE_SEEDS = (11, 12, 13)


def part_end_to_end_replicates() -> dict:
    """``end_to_end`` repeated with other sensor-noise seeds (raw brackets) and ``abs simulate``
    seeds, the same renders, settings and start: for each seed the simulated capture at
    downsample 1 and 2, the bilinear build at downsample 1 and 2 and the superpixel build at
    downsample 1. Per variant: each replicate's errors and their mean and standard deviation
    across replicates (run-to-run spread, to set beside the fits' Laplace standard errors).
    Measured before builds wrote ``blur_px``: rerunning it now fits blurred renderings."""
    gain = E2E["gain_dn_per_s"]
    return _replicates(E2E, (("simulate", "simulated", 1.0, 1),
                             ("simulate_downsample2", "simulated", 1.0, 2),
                             ("built_from_raw", "bilinear", gain, 1),
                             ("built_from_raw_downsample2", "bilinear", gain, 2),
                             ("built_from_raw_superpixel", "superpixel", gain, 1)))


def part_end_to_end_blur_replicates() -> dict:
    """``end_to_end_blur``'s comparison (128 samples per pixel) repeated with the replicate
    seeds: the simulated capture, the bilinear build with its ``blur_px`` and without it, and
    the superpixel build, all at downsample 1. Measured before builds wrote ``processing``
    (rerunning it now fits the builds through their footprints)."""
    gain = E2E["gain_dn_per_s"]
    return _replicates({**E2E, "fit_spp": 128},
                       (("simulate", "simulated", 1.0, 1), ("built_from_raw", "bilinear", gain, 1),
                        ("built_from_raw_unblurred", "unblurred", gain, 1),
                        ("built_from_raw_superpixel", "superpixel", gain, 1)))


def _e2e_captures(tmp: Path, scene, compiled, views, cfg: dict, simulate_seed: int,
                  noise_seed: int) -> dict:
    """The end-to-end captures in ``tmp``: ``simulated`` (``abs simulate``), the ``bilinear``
    and ``superpixel`` builds of the raw brackets (with their ``processing``: fits render the
    sensor sites, :mod:`abs.render.footprint`), ``gaussian`` (the bilinear build without
    ``processing``: fits blur by ``blur_px``) and ``unblurred`` (without either). Returns the two
    builds' ``blur_px``."""
    from abs.acquisition.build import build_capture
    from abs.io.capture import save_capture
    from abs.simulate import simulate_capture

    simulate_capture(scene, tmp / "simulated", n_cameras=cfg["views"], width=cfg["width"],
                     height=cfg["height"], spp=cfg["truth_spp"], shot_noise=1e-4,
                     read_noise=0.003, seed=simulate_seed)
    raw = _e2e_raw_brackets(compiled, views, tmp / "raw", cfg, noise_seed=noise_seed)
    bilinear, _ = build_capture(raw / "build.json", tmp / "bilinear")
    superpixel, _ = build_capture(raw / "build.json", tmp / "superpixel", demosaic="superpixel")
    # Without the build's processing: the renderer draws sharp pixels (unblurred) or blurs them
    # by blur_px's Gaussian (gaussian), as readers that ignore ``processing`` do.
    save_capture(tmp / "unblurred", bilinear.views, blur_px=[0, 0, 0], processing={})
    save_capture(tmp / "gaussian", bilinear.views, processing={})
    return {"bilinear": list(bilinear.views[0].blur_px),
            "superpixel": list(superpixel.views[0].blur_px)}


def _replicates(cfg: dict, variants) -> dict:
    """Fits of ``variants`` (label, capture folder, unit, downsample) for each replicate seed
    (:func:`_e2e_captures`' folders)."""
    t0 = time.perf_counter()
    scene_path, scene, compiled, views, truth = _e2e_setup()
    out: dict = {"config": f"as end_to_end, fit_spp {cfg['fit_spp']}; sensor-noise seeds "
                           + ", ".join(map(str, E2E_REPLICATE_SEEDS))
                           + " (raw), the same seeds for abs simulate",
                 "truth": truth, "replicates": {}}
    for seed in E2E_REPLICATE_SEEDS:
        rep: dict = {}
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            _e2e_captures(tmp, scene, compiled, views, cfg, simulate_seed=seed, noise_seed=seed)
            for label, folder, unit, ds in variants:
                rep[label] = _e2e_fit(scene_path, tmp / folder, unit, ds, truth, cfg)
                print(seed, label, np.round(rep[label]["glass_absorption_error"], 2),
                      flush=True)
        out["replicates"][str(seed)] = rep
    out["summary"] = {}
    for label, *_ in variants:
        err = np.array([r[label]["glass_absorption_error"]
                        for r in out["replicates"].values()])
        scale = np.array([r[label]["environment_scale_rel_error"]
                          for r in out["replicates"].values()])
        se = np.array([r[label]["glass_absorption_stderr"] for r in out["replicates"].values()])
        out["summary"][label] = {
            "glass_absorption_error_mean": err.mean(0).tolist(),
            "glass_absorption_error_sd": err.std(0, ddof=1).tolist(),
            "glass_absorption_stderr_mean": se.mean(0).tolist(),
            "environment_scale_rel_error_mean": float(scale.mean()),
            "environment_scale_rel_error_sd": float(scale.std(ddof=1))}
    out["seconds"] = time.perf_counter() - t0
    return out


def part_end_to_end_exr() -> dict:
    """``end_to_end``'s built capture without the mosaic: the same distorted renders written as
    one linear EXR frame per view (noise as ``abs simulate``'s), undistorted by ``build_capture``
    and fitted at downsample 1. Separates the demosaic's share of the absorption bias from the
    resampling's (distortion simulated at 2x, then undistortion). The build writes the
    undistortion's own blur (``blur_px``, no demosaic); fitted at 128 samples per pixel as
    ``end_to_end_blur``."""
    from abs.acquisition.build import build_capture
    from abs.acquisition.camera_file import CameraModel, write_camera_file
    from abs.fitting import FitSettings, fit
    from abs.io.images import write_exr
    from abs.render import Camera
    from abs.simulate import add_sensor_noise

    t0 = time.perf_counter()
    cfg = {**E2E, "fit_spp": 128}
    scene_path, _, compiled, views, _ = _e2e_setup()
    W, H, n = cfg["width"], cfg["height"], cfg["supersample"]
    dist = np.array(cfg["distortion"])
    truth_abs = compiled.get("glass.absorption").copy()
    rng = np.random.default_rng(3)
    out: dict = {"config": "as end_to_end, fit_spp 128; frames: one linear EXR per view, noise "
                           "shot 1e-4, read 0.003 (abs simulate's)"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cams, build_views = {}, []
        for i, view in enumerate(views):
            K = np.asarray(view["K"], np.float64)
            f_r, w_r, h_r = render_pinhole_size(K, dist, W, H, n)
            K_r = np.array([[f_r, 0, (w_r - 1) / 2], [0, f_r, (h_r - 1) / 2], [0, 0, 1]])
            cam = Camera(K_r, np.asarray(view["R"]), np.asarray(view["t"]), w_r, h_r)
            pin = compiled.render(cam, spp=cfg["truth_spp"] // (n * n) or 1, seed=500 + i).numpy()
            rgb = distort_render(pin, f_r, K, dist, W, H, n)
            write_exr(tmp / f"cam{i}.exr", add_sensor_noise(rgb, 1e-4, 0.003, rng))
            cams[f"cam{i}"] = CameraModel(W, H, K, dist, R=np.asarray(view["R"]),
                                          t=np.asarray(view["t"]))
            build_views.append({"name": view["name"], "camera": f"cam{i}",
                                "frames": [f"cam{i}.exr"], "holdout": i == cfg["views"] - 1})
        write_camera_file(tmp / "cameras.json", cams)
        (tmp / "build.json").write_text(json.dumps({"cameras": "cameras.json",
                                                    "views": build_views}))
        built, _ = build_capture(tmp / "build.json", tmp / "built")
        out["blur_px"] = list(built.views[0].blur_px)
        settings = FitSettings(spp=cfg["fit_spp"], max_iterations=cfg["max_iterations"],
                               refinement_steps=cfg["refinement_steps"])
        initial = {"environment.scale": [cfg["start_scale_factor"]],
                   "glass.absorption": cfg["start_absorption"]}
        result = fit(scene_path, tmp / "built", settings=settings, initial=initial)
    stderr = result.vector.split(result.uncertainty.stderr)
    absorption = np.ravel(result.values["glass.absorption"])
    se = np.ravel(stderr["glass.absorption"])
    out.update({
        "environment_scale": float(np.ravel(result.values["environment.scale"])[0]),
        "environment_scale_stderr": float(np.ravel(stderr["environment.scale"])[0]),
        "glass_absorption": absorption.tolist(), "glass_absorption_stderr": se.tolist(),
        "glass_absorption_error": (absorption - truth_abs).tolist(),
        "glass_absorption_z": ((absorption - truth_abs) / se).tolist(),
        "holdout_rmse": result.metrics.get("holdout_rmse"),
        "seconds": time.perf_counter() - t0})
    return out


def part_pipeline_contrast() -> dict:
    """How much of a fine pattern's contrast survives the raw path of ``end_to_end`` (distortion
    resampling at 2x, RGGB mosaic, bilinear demosaic, bilinear undistortion) against the ideal
    pinhole image at the capture's K (area-integrated), per pattern period in pixels. A fitted
    model renders the ideal image: lost contrast is a bias the fit must absorb."""
    from abs.acquisition.camera_file import CameraModel
    from abs.acquisition.demosaic import cfa_masks, demosaic_bilinear, demosaic_superpixel
    from abs.acquisition.undistort import pinhole_K, superpixel_camera, undistort_image
    from abs.camera.pinhole import intrinsics_from_fov

    W, H, n = E2E["width"], E2E["height"], E2E["supersample"]
    K = intrinsics_from_fov(W, H, np.radians(30.0))
    dist = np.array(E2E["distortion"])
    cam = CameraModel(W, H, K, dist)
    K_new = pinhole_K(cam)
    f_r, w_r, h_r = render_pinhole_size(K, dist, W, H, n)
    masks = cfa_masks((H, W), "RGGB")

    def pattern(xn, yn, period):
        return 1 + 0.5 * np.sin(2 * np.pi * xn * K[0, 0] / period) \
            * np.sin(2 * np.pi * yn * K[0, 0] / period * 1.1)

    half = superpixel_camera(cam)
    K_half = pinhole_K(half)
    out: dict = {"pattern": "1 + 0.5 sin(2 pi x / P) sin(2 pi 1.1 y / P), grey, P in pixels",
                 "contrast_kept": {},
                 "contrast_kept_64x48": {},
                 "note_64x48": "against the ideal image area-integrated over 64x48 pixels (what "
                               "a fit at that resolution renders): 'superpixel' is the superpixel "
                               "build (half-resolution camera), 'bilinear_downsample2' the "
                               "bilinear build box-averaged by 2 (fit downsample 2)"}
    ys, xs = np.mgrid[0:h_r, 0:w_r]
    s = 4
    yy, xx = np.mgrid[0:H * s, 0:W * s]
    u, v = (xx - (s - 1) / 2) / s, (yy - (s - 1) / 2) / s
    yh, xh = np.mgrid[0:(H // 2) * s, 0:(W // 2) * s]
    uh, vh = (xh - (s - 1) / 2) / s, (yh - (s - 1) / 2) / s
    inner = (slice(8, -8), slice(8, -8))
    inner_h = (slice(4, -4), slice(4, -4))

    def kept_of(ref_img, got, where):
        a = ref_img[where] - np.mean(ref_img[where])
        return {c: float(np.sum(a * (got[where][..., i] - np.mean(got[where][..., i])))
                         / np.sum(a * a)) for i, c in enumerate("RGB")}
    for period in (3, 4, 6, 8, 12, 16):
        pin = pattern((xs - (w_r - 1) / 2) / f_r, (ys - (h_r - 1) / 2) / f_r, period)
        img = distort_render(np.repeat(pin[..., None], 3, -1).astype(np.float32), f_r, K, dist,
                             W, H, n)
        full = undistort_image(demosaic_bilinear(np.sum(img * masks, -1), "RGGB"), cam, K_new)
        no_demosaic = undistort_image(img, cam, K_new)
        ref = cv2.resize(pattern((u - K_new[0, 2]) / K_new[0, 0], (v - K_new[1, 2]) / K_new[1, 1],
                                 period).astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
        a = ref[inner] - 1
        kept = {c: float(np.sum(a * (full[inner][..., i] - 1)) / np.sum(a * a))
                for i, c in enumerate("RGB")}
        kept["without_demosaic"] = float(np.sum(a * (no_demosaic[inner][..., 0] - 1)) / np.sum(a * a))
        out["contrast_kept"][str(period)] = kept
        # At 64x48: the superpixel build, and the bilinear build averaged over 2x2 pixels.
        sp = undistort_image(demosaic_superpixel(np.sum(img * masks, -1), "RGGB"), half, K_half)
        ref_sp = cv2.resize(pattern((uh - K_half[0, 2]) / K_half[0, 0],
                                    (vh - K_half[1, 2]) / K_half[1, 1], period).astype(np.float32),
                            (W // 2, H // 2), interpolation=cv2.INTER_AREA)
        ref_ds = cv2.resize(ref, (W // 2, H // 2), interpolation=cv2.INTER_AREA)
        ds = cv2.resize(full, (W // 2, H // 2), interpolation=cv2.INTER_AREA)
        out["contrast_kept_64x48"][str(period)] = {
            "superpixel": kept_of(ref_sp, sp, inner_h),
            "bilinear_downsample2": kept_of(ref_ds, ds, inner_h)}
    return out


# ---------------------------------------------------------------------------------------------

PARTS = {"real_stereo": part_real_stereo, "real_hdr": part_real_hdr,
         "synthetic_calibration": part_synthetic_calibration,
         "synthetic_hdr": part_synthetic_hdr, "end_to_end": part_end_to_end,
         "pipeline_contrast": part_pipeline_contrast, "end_to_end_exr": part_end_to_end_exr,
         "end_to_end_superpixel": part_end_to_end_superpixel,
         "end_to_end_replicates": part_end_to_end_replicates,
         "end_to_end_blur": part_end_to_end_blur,
         "end_to_end_blur_replicates": part_end_to_end_blur_replicates,
         "end_to_end_blur_render_seeds": part_end_to_end_blur_render_seeds,
         "end_to_end_footprint": part_end_to_end_footprint,
         "end_to_end_footprint_replicates": part_end_to_end_footprint_replicates}


def _f(v, fmt="{:.3f}") -> str:
    return "-" if v is None else fmt.format(v)


def _absorption_errors(x: dict) -> str:
    """An end-to-end fit's absorption errors with their standard errors, 1/m."""
    return ", ".join(f"{v:+.2f} ± {se:.2f}" for v, se in
                     zip(x["glass_absorption_error"], x["glass_absorption_stderr"]))


def _scale_and_absorption_errors(x: dict) -> str:
    """An end-to-end fit's relative scale error (± its standard error), then its absorption's."""
    return (f"{100 * x['environment_scale_rel_error']:+.2f} % "
            f"(± {100 * x['environment_scale_stderr']:.2f} %); " + _absorption_errors(x))


def write_markdown(results: dict, path: Path) -> None:
    parts = results.get("parts", {})
    lines = ["# Acquisition benchmark", "",
             "Written by `benchmarks/acquisition.py`; numbers from `acquisition.json`.", "",
             "| Part | Measure | Value | Target / note |", "|---|---|---|---|"]
    s = parts.get("real_stereo")
    if s and "skipped" not in s:
        for cam in ("left", "right"):
            c = s[cam]
            d = c["difference"]
            head = "real stereo 640x512" if cam == "left" else ""
            lines += [f"| {head} | {cam}: RMS reprojection (25 views) | "
                      f"{c['rms_px']:.3f} px | OpenCV sample run: 0.149 / 0.161 px |",
                      f"| | {cam}: fx, fy vs reference | {100 * d['fx_rel']:+.2f} %, "
                      f"{100 * d['fy_rel']:+.2f} % | reference has fx = fy, rational model |",
                      f"| | {cam}: cx, cy vs reference | {d['cx_px']:+.2f}, {d['cy_px']:+.2f} px | |",
                      f"| | {cam}: whole model vs reference, pixel positions | median "
                      f"{d['model_pixel_position']['median_px']:.2f}, max "
                      f"{d['model_pixel_position']['max_px']:.2f} px | |"]
        st = s["stereo"]
        lines += [f"| | stereo RMS (20 pairs) | {st['rms_px']:.3f} px | |",
                  f"| | epipolar error, 5 held-out pairs | RMS {st['heldout_epipolar_px']['rms']:.3f},"
                  f" max {st['heldout_epipolar_px']['max']:.3f} px | |",
                  f"| | rotation vs reference | {st['difference']['rotation_deg']:.3f} deg | |",
                  f"| | baseline direction vs reference | {st['difference']['T_direction_deg']:.2f} deg"
                  f" | length: {st['baseline_squares']:.2f} squares (reference "
                  f"{st['reference']['baseline']:.1f}, its units) |"]
    r = parts.get("real_hdr")
    if r and "skipped" not in r:
        a = r["all_bands"]
        lines += [f"| real raw stacks (Llanos, {len(r['bands'])} bands x 7 exposures) | relative "
                  f"spread across exposures ({a['patches_measured']} patch-bands) | median "
                  f"{100 * a['relative_spread']['median']:.2f} %, max "
                  f"{100 * a['relative_spread']['max']:.2f} % | |",
                  f"| | deviation from merged x t | median "
                  f"{100 * a['max_deviation_from_linear']['median']:.2f} %, max "
                  f"{100 * a['max_deviation_from_linear']['max']:.2f} % | |",
                  f"| | log-log slope of patch mean vs exposure | {a['loglog_slope']['min']:.4f} .. "
                  f"{a['loglog_slope']['max']:.4f} | 1 = linear |"]
    c = parts.get("synthetic_calibration")
    if c:
        p = c["pixel_position_error_px"]
        lines += [f"| Mitsuba board, {c['found']} poses, 320x240 | K error (fx, fy, cx, cy) | max "
                  f"{100 * c['K_error_rel']['max_abs']:.3f} % | < 0.5 % |",
                  f"| | distortion pixel positions, where boards were seen | max "
                  f"{p['distortion_only_seen']['max']:.3f} px (whole model {p['model_seen']['max']:.3f})"
                  f" | < 0.1 px |",
                  f"| | same, whole image (extrapolated corners) | max "
                  f"{p['distortion_only_whole_image']['max']:.3f} px (whole model "
                  f"{p['model_whole_image']['max']:.3f}) | |",
                  f"| | corner detection error | RMS {c['corner_error_px']['rms']:.3f} px | "
                  f"blur {c['blur_sigma_px']} px, noise {c['noise_sd']} |",
                  f"| | RMS reprojection | {c['rms_px']:.3f} px | |"]
    h = parts.get("synthetic_hdr")
    if h:
        m = h["mosaic"]
        lines += [f"| simulated sensor, 11 exposures 1..1024 ms | merged mosaic vs truth, error / "
                  f"expected noise | RMS {m['normalised_error_rms']:.2f}, mean "
                  f"{m['normalised_error_mean']:+.3f} | within noise: ~1 |",
                  f"| | relative bias | {100 * m['relative_bias']:+.3f} % | |",
                  f"| | demosaiced (builder's loader) vs demosaiced truth | median "
                  f"{100 * h['demosaiced']['relative_error_median_abs']:.2f} %, bias "
                  f"{100 * h['demosaiced']['relative_bias']:+.3f} % | |",
                  f"| | 8-bit gamma bracket, Debevec: absolute log error | median "
                  f"{h['jpeg_like']['log_error_median_abs']:.3f}, p95 "
                  f"{h['jpeg_like']['log_error_p95_abs']:.3f} | |"]
    e = parts.get("end_to_end")
    if e:
        sp = parts.get("end_to_end_superpixel") or {}
        for label in ("simulate", "built_from_raw", "simulate_downsample2",
                      "built_from_raw_downsample2", "built_from_raw_superpixel"):
            x = e.get(label) or sp.get(label)
            if x:
                cfg = e["config"]
                note = (" (64x48 capture, fitted at downsample 1)"
                        if label == "built_from_raw_superpixel" else "")
                lines.append(
                    f"| end to end, default scene, {cfg['views']} views {cfg['width']}x"
                    f"{cfg['height']} | {label}: environment.scale error; glass.absorption error "
                    f"(1/m, truth {e['truth']['glass.absorption']}) | "
                    + _scale_and_absorption_errors(x)
                    + f" | holdout RMSE {x['holdout_rmse_in_scene_units'].get('before', 0):.4f} -> "
                    f"{x['holdout_rmse_in_scene_units'].get('after', 0):.4f}{note} |")
    eb = parts.get("end_to_end_blur")
    if eb:
        notes = {"built_from_raw_unblurred": "the same build, blur_px removed",
                 "built_from_raw_superpixel": "64x48 capture, fitted at downsample 1"}
        for label in ("simulate", "built_from_raw", "built_from_raw_unblurred",
                      "simulate_downsample2", "built_from_raw_downsample2",
                      "built_from_raw_superpixel"):
            x = eb[label]
            lines.append(
                f"| {'end to end, capture blur modelled (one run)' if label == 'simulate' else ''} "
                f"| {label}: environment.scale error; glass.absorption error (1/m) | "
                + _scale_and_absorption_errors(x) + f" | {notes.get(label, '')} |")
        lines.append("| | blur_px written by the builds (R, G, B) | bilinear "
                     + ", ".join(f"{b:.3f}" for b in eb["blur_px"]["bilinear"]) + "; superpixel "
                     + ", ".join(f"{b:.3f}" for b in eb["blur_px"]["superpixel"]) + " | |")
    ef = parts.get("end_to_end_footprint")
    if ef:
        notes = {"built_from_raw": "processing rendered exactly (footprint)",
                 "built_from_raw_gaussian": "the same build through blur_px (processing removed)",
                 "built_from_raw_downsample2": "footprint, fitted at downsample 2",
                 "built_from_raw_superpixel": "footprint; 64x48 capture, fitted at downsample 1"}
        for label in ("simulate", "built_from_raw", "built_from_raw_gaussian",
                      "built_from_raw_downsample2", "built_from_raw_superpixel"):
            x = ef[label]
            lines.append(
                f"| {'end to end, the build processing rendered exactly (one run)' if label == 'simulate' else ''} "
                f"| {label}: environment.scale error; glass.absorption error (1/m) | "
                + _scale_and_absorption_errors(x) + f" | {notes.get(label, '')} |")
    rs = parts.get("end_to_end_blur_render_seeds")
    if rs:
        for key in ("700", "900"):
            x = rs[key]
            lines.append(
                f"| {'capture blur modelled, other truth renders' if key == '700' else ''} "
                f"| built_from_raw, scene renders seeded {key}: glass.absorption error (1/m) | "
                + _absorption_errors(x) + " | the renders behind the raw frames (500 elsewhere) |")
    for part, heading in (("end_to_end_replicates", "same, {n} more noise seeds"),
                          ("end_to_end_blur_replicates",
                           "capture blur modelled, {n} more noise seeds"),
                          ("end_to_end_footprint_replicates",
                           "processing rendered exactly, {n} more noise seeds")):
        rp = parts.get(part)
        if not rp:
            continue
        n_rep = len(rp["replicates"])
        for label, x in rp["summary"].items():
            lines.append(
                f"| {heading.format(n=n_rep) if label == 'simulate' else ''} "
                    f"| {label}: environment.scale error; glass.absorption error (1/m), mean ± "
                    f"spread (sd) over the seeds | {100 * x['environment_scale_rel_error_mean']:+.2f} % "
                    f"(± {100 * x['environment_scale_rel_error_sd']:.2f} %); "
                    + ", ".join(f"{v:+.2f} ± {sd:.2f}" for v, sd in
                                zip(x["glass_absorption_error_mean"], x["glass_absorption_error_sd"]))
                    + " | fits' own standard errors: "
                    + ", ".join(f"{v:.2f}" for v in x["glass_absorption_stderr_mean"]) + " |")
    ex = parts.get("end_to_end_exr")
    if ex:
        lines.append(
            "| | built from linear EXR frames (no mosaic, no demosaic): environment.scale error; "
            "glass.absorption error (1/m) | "
            f"{100 * (ex['environment_scale'] - 1):+.2f} % (± {100 * ex['environment_scale_stderr']:.2f} %); "
            + _absorption_errors(ex)
            + " | isolates the resampling's share"
            + (f"; blur_px {ex['blur_px'][0]:.3f} modelled, 128 spp |" if "blur_px" in ex
               else " |"))
    pc = parts.get("pipeline_contrast")
    if pc:
        for period, kept in pc["contrast_kept"].items():
            lines.append(f"| {'raw path contrast (end-to-end settings)' if period == '3' else ''} "
                         f"| pattern period {period} px: contrast kept R, G, B (no demosaic) | "
                         f"{kept['R']:.2f}, {kept['G']:.2f}, {kept['B']:.2f} "
                         f"({kept['without_demosaic']:.2f}) | 1 = none lost |")
        for period, kept in pc.get("contrast_kept_64x48", {}).items():
            sp, ds = kept["superpixel"], kept["bilinear_downsample2"]
            lines.append(f"| {'same, fitted at 64x48' if period == '3' else ''} "
                         f"| pattern period {period} px (of 128x96): contrast kept R, G, B: "
                         f"superpixel; bilinear + downsample 2 | "
                         f"{sp['R']:.2f}, {sp['G']:.2f}, {sp['B']:.2f}; "
                         f"{ds['R']:.2f}, {ds['G']:.2f}, {ds['B']:.2f} | against the ideal "
                         f"64x48 image |")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default=",".join(PARTS), help="comma-separated parts to run")
    ap.add_argument("--force", action="store_true", help="rerun parts already in the results")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    results = json.loads(args.out.read_text()) if args.out.is_file() else {}
    results.setdefault("parts", {})
    results["machine"] = platform.processor() or platform.machine()
    for name in args.parts.split(","):
        if name not in PARTS:
            raise SystemExit(f"unknown part {name!r}; known: {', '.join(PARTS)}")
        if name in results["parts"] and not args.force:
            print(f"{name}: already in {args.out}, skipped (--force to rerun)")
            continue
        print(f"{name} ...", flush=True)
        results["parts"][name] = PARTS[name]()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2))
        write_markdown(results, args.out.with_suffix(".md"))
        print(json.dumps(results["parts"][name], indent=1)[:3000], flush=True)
    write_markdown(results, args.out.with_suffix(".md"))


if __name__ == "__main__":
    main()
