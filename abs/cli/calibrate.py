"""``abs calibrate intrinsics|stereo|extrinsics``: camera calibration with a board.

Results go to a camera file (:mod:`abs.acquisition.camera_file`); an existing file is updated
camera by camera, so one file can hold a rig. ``--report DIR`` writes the figures (coverage,
RMS per view, detected corners) and ``report.json``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np


def add_parser(sub) -> None:
    p = sub.add_parser("calibrate", help="calibrate cameras from photographs of a board")
    kinds = p.add_subparsers(dest="kind", required=True)

    def common(q) -> None:
        q.add_argument("--board", required=True,
                       help="board: checkerboard:COLSxROWS:SIZE counting inner corners (e.g. "
                            "checkerboard:9x6:25mm) or charuco:COLSxROWS:SQUARE:MARKER:DICT "
                            "counting squares (e.g. charuco:7x5:30mm:22mm:DICT_5X5_100)")
        q.add_argument("--out", type=Path, required=True, help="camera file (JSON) to write/update")
        q.add_argument("--report", type=Path, help="folder for figures and report.json")

    q = kinds.add_parser("intrinsics", help="K and distortion from many varied views")
    q.add_argument("images", nargs="+", type=Path)
    q.add_argument("--camera", default="camera", help="camera name in the camera file")
    q.add_argument("--drop-outliers", action="store_true",
                   help="recalibrate without the views flagged as outliers")
    common(q)
    q.set_defaults(run=_run_intrinsics)

    q = kinds.add_parser("stereo", help="a camera pair: both intrinsics, then R, T, E, F")
    q.add_argument("--left", nargs="+", type=Path, required=True, help="camera-1 images")
    q.add_argument("--right", nargs="+", type=Path, required=True,
                   help="camera-2 images, paired with --left in order")
    q.add_argument("--names", nargs=2, default=("left", "right"), metavar=("CAM1", "CAM2"))
    q.add_argument("--holdout", type=int, default=0,
                   help="last N pairs kept out of the fit to measure the epipolar error")
    common(q)
    q.set_defaults(run=_run_stereo)

    q = kinds.add_parser("extrinsics", help="a camera's pose from a board placed in the scene "
                                            "(the board defines the world axes)")
    q.add_argument("image", type=Path)
    q.add_argument("--camera", required=True, help="camera (already in --out) to place")
    q.add_argument("--rig", nargs="*", default=[], metavar="CAM",
                   help="other cameras of the same rig (posed relative to --camera by stereo), "
                        "moved with it into the board's world frame")
    common(q)
    q.set_defaults(run=_run_extrinsics)


def _detect(paths: list[Path], board, label: str):
    from tqdm import tqdm

    from abs.acquisition.detection import detect_in_files

    with tqdm(total=len(paths), desc=f"detect {label}", unit="image") as bar:
        return detect_in_files(paths, board, progress=bar.update)


def _update_camera_file(path: Path, cameras: dict) -> None:
    from abs.acquisition.camera_file import read_camera_file, write_camera_file

    existing = read_camera_file(path) if path.exists() else {}
    existing.update(cameras)
    write_camera_file(path, existing)


def _intrinsics(paths: list[Path], board, label: str, drop_outliers: bool, det=None):
    from abs.acquisition.intrinsics import calibrate_intrinsics

    det = _detect(paths, board, label) if det is None else det
    found = det.found
    names = [det.paths[i].name for i in found]
    calib = calibrate_intrinsics([det.corners[i] for i in found], board.object_points(),
                                 det.width, det.height, names)
    if drop_outliers and calib.outliers:
        keep = [k for k, n in enumerate(names) if n not in calib.outliers]
        flagged = calib.outliers
        calib = calibrate_intrinsics([det.corners[found[k]] for k in keep], board.object_points(),
                                     det.width, det.height, [names[k] for k in keep])
        calib.outliers = {**flagged, **calib.outliers}
    return det, calib


def _summary(label: str, det, calib) -> dict[str, Any]:
    missing = [det.paths[i].name for i, c in enumerate(det.corners) if c is None]
    print(f"{label}: board found in {len(det.found)} of {len(det.paths)} images"
          + (f" (not in {', '.join(missing)})" if missing else ""))
    print(f"  RMS reprojection error {calib.rms_px:.3f} px; per view "
          f"{calib.view_rms_px.min():.3f} .. {calib.view_rms_px.max():.3f} px")
    K = calib.K
    print(f"  fx {K[0, 0]:.2f} +- {calib.std['fx']:.2f}, fy {K[1, 1]:.2f} +- {calib.std['fy']:.2f}, "
          f"cx {K[0, 2]:.2f} +- {calib.std['cx']:.2f}, cy {K[1, 2]:.2f} +- {calib.std['cy']:.2f} px")
    print("  distortion k1 k2 p1 p2 k3: " + ", ".join(
        f"{v:.4f} +- {calib.std[n]:.4f}" for n, v in zip(("k1", "k2", "p1", "p2", "k3"), calib.dist)))
    print(f"  coverage {100 * calib.coverage:.0f} % of the image"
          + (" (POOR: add views with the board near the image edges and corners)"
             if calib.poor_coverage else ""))
    for name, reason in calib.outliers.items():
        print(f"  outlier {name}: {reason}")
    return {"images": [str(p) for p in det.paths], "not_found": missing,
            "rms_px": calib.rms_px, "view_rms_px": dict(zip(calib.names, calib.view_rms_px.tolist())),
            "K": calib.K.tolist(), "distortion": calib.dist.tolist(), "std": calib.std,
            "coverage": calib.coverage, "poor_coverage": calib.poor_coverage,
            "outliers": calib.outliers}


def _figures(report: Path, label: str, det, calib, board) -> None:
    from abs.acquisition.detection import read_gray
    from abs.acquisition.figures import (write_coverage_png, write_detection_png,
                                         write_view_rms_png)
    from abs.acquisition.intrinsics import coverage_map

    report.mkdir(parents=True, exist_ok=True)
    corners = [det.corners[i] for i in det.found]
    write_coverage_png(report / f"{label}_coverage.png", coverage_map(corners, det.width, det.height))
    write_view_rms_png(report / f"{label}_view_rms.png", calib.names, calib.view_rms_px,
                       list(calib.outliers))
    (report / f"{label}_corners").mkdir(exist_ok=True)
    for path, c in zip(det.paths, det.corners):
        write_detection_png(report / f"{label}_corners" / f"{path.stem}.png", read_gray(path), c,
                            board.inner_corners)


def _run_intrinsics(args) -> int:
    from abs.acquisition.board import parse_board
    from abs.acquisition.camera_file import CameraModel

    board = parse_board(args.board, field="--board")
    det, calib = _intrinsics(args.images, board, args.camera, args.drop_outliers)
    summary = _summary(args.camera, det, calib)
    _update_camera_file(args.out, {args.camera: CameraModel(calib.width, calib.height, calib.K,
                                                            calib.dist, rms_px=calib.rms_px)})
    if args.report:
        _figures(args.report, args.camera, det, calib, board)
        (args.report / "report.json").write_text(json.dumps({args.camera: summary}, indent=2))
    print(f"wrote camera {args.camera!r} to {args.out}")
    return 0


def _run_stereo(args) -> int:
    from abs.acquisition.board import parse_board
    from abs.acquisition.camera_file import CameraModel
    from abs.acquisition.stereo import calibrate_stereo, epipolar_errors_px
    from abs.errors import InputError

    if len(args.left) != len(args.right):
        raise InputError(None, "--right", f"{len(args.right)} images for {len(args.left)} in --left")
    board = parse_board(args.board, field="--board")
    n1, n2 = args.names
    d1, d2 = _detect(args.left, board, n1), _detect(args.right, board, n2)
    if (d1.width, d1.height) != (d2.width, d2.height):
        raise InputError(args.right[0], "", f"image size {d2.width}x{d2.height} differs from "
                                            f"{n1}'s {d1.width}x{d1.height}: mixed image sizes")
    d1, c1 = _intrinsics(args.left, board, n1, False, d1)
    d2, c2 = _intrinsics(args.right, board, n2, False, d2)
    # A pair counts when both cameras saw at least 4 of the same corners (a ChArUco board may be
    # seen in part; a checkerboard is seen whole or not at all).
    both = [i for i in range(len(args.left)) if d1.corners[i] is not None
            and d2.corners[i] is not None
            and np.sum(np.isfinite(d1.corners[i]).all(1) & np.isfinite(d2.corners[i]).all(1)) >= 4]
    held = both[len(both) - args.holdout:] if args.holdout else []
    train = [i for i in both if i not in held]
    st = calibrate_stereo([d1.corners[i] for i in train], [d2.corners[i] for i in train],
                          board.object_points(), c1.K, c1.dist, c2.K, c2.dist, d1.width, d1.height)
    report: dict[str, Any] = {n1: _summary(n1, d1, c1), n2: _summary(n2, d2, c2)}
    angle = float(np.degrees(np.linalg.norm(__import__("cv2").Rodrigues(st.R)[0])))
    print(f"stereo: {len(train)} pairs, RMS {st.rms_px:.3f} px, baseline {st.baseline_m * 1000:.2f} mm,"
          f" rotation {angle:.3f} deg, T = {np.round(st.T * 1000, 2).tolist()} mm")
    report["stereo"] = {"pairs": len(train), "rms_px": st.rms_px, "R": st.R.tolist(),
                        "T": st.T.tolist(), "E": st.E.tolist(), "F": st.F.tolist()}
    if held:
        errs = np.concatenate([epipolar_errors_px(d1.corners[i], d2.corners[i], st.F, c1.K,
                                                  c1.dist, c2.K, c2.dist) for i in held])
        rms = float(np.sqrt(np.mean(errs ** 2)))
        print(f"  held-out pairs {len(held)}: epipolar error RMS {rms:.3f} px, max {errs.max():.3f} px")
        report["stereo"]["heldout_epipolar_rms_px"] = rms
    _update_camera_file(args.out, {
        n1: CameraModel(c1.width, c1.height, c1.K, c1.dist, rms_px=c1.rms_px),
        n2: CameraModel(c2.width, c2.height, c2.K, c2.dist, st.R, st.T, rms_px=c2.rms_px)})
    if args.report:
        _figures(args.report, n1, d1, c1, board)
        _figures(args.report, n2, d2, c2, board)
        (args.report / "report.json").write_text(json.dumps(report, indent=2))
    print(f"wrote cameras {n1!r}, {n2!r} to {args.out}")
    return 0


def _run_extrinsics(args) -> int:
    from abs.acquisition.board import detect_corners, parse_board
    from abs.acquisition.camera_file import read_camera_file
    from abs.acquisition.detection import read_gray
    from abs.acquisition.extrinsics import board_pose
    from abs.errors import InputError

    board = parse_board(args.board, field="--board")
    cameras = read_camera_file(args.out)
    if args.camera not in cameras:
        raise InputError(args.out, f"cameras.{args.camera}", "no such camera; calibrate its "
                                                             "intrinsics first")
    cam = cameras[args.camera]
    gray = read_gray(args.image)
    if (gray.shape[1], gray.shape[0]) != (cam.width, cam.height):
        raise InputError(args.image, "", f"image is {gray.shape[1]}x{gray.shape[0]}, camera "
                                         f"{args.camera} is {cam.width}x{cam.height}")
    corners = detect_corners(gray, board)
    if corners is None:
        raise InputError(args.image, "", f"board {board.spec} not found")
    R, t, rms = board_pose(corners, board.object_points(), cam.K, cam.distortion)
    # The file's poses so far are in a rig frame (stereo puts camera 1 at its origin); the board
    # view gives world -> this camera, hence world -> rig, which places the rig's other cameras.
    R_rig = cam.R.T @ R
    t_rig = cam.R.T @ (t - cam.t)
    moved = {}
    for name in [args.camera, *args.rig]:
        if name not in cameras:
            raise InputError(args.out, f"cameras.{name}", "no such camera (named in --rig)")
        other = cameras[name]
        other.R, other.t = other.R @ R_rig, other.R @ t_rig + other.t
        moved[name] = other
    _update_camera_file(args.out, moved)
    print(f"{args.camera}: pose from the board, RMS {rms:.3f} px, camera centre "
          f"{np.round(-R.T @ t, 4).tolist()} m in board coordinates")
    if args.report:
        args.report.mkdir(parents=True, exist_ok=True)
        (args.report / "report.json").write_text(json.dumps(
            {"camera": args.camera, "rms_px": rms, "R": R.tolist(), "t": t.tolist()}, indent=2))
    return 0
