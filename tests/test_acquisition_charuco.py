"""ChArUco boards: parsing ``charuco:COLSxROWS:SQUARE:MARKER:DICT``, detection of whole and partial
boards, and intrinsic calibration from per-view subsets of the corners.

The views are synthetic with known truth: the board's own picture (``Board.image``, drawn by
OpenCV's ``CharucoBoard.generateImage``) seen at the poses of
:func:`abs.acquisition.synthetic.board_views` through a known K and a small distortion
(:func:`abs.acquisition.synthetic.board_images`), with a little noise, quantised to 8 bits.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from abs.acquisition.board import detect_corners, parse_board, seen_points
from abs.acquisition.camera_file import read_camera_file
from abs.acquisition.extrinsics import board_pose
from abs.acquisition.intrinsics import calibrate_intrinsics, coverage_map
from abs.acquisition.stereo import calibrate_stereo, epipolar_errors_px
from abs.acquisition.synthetic import board_images, board_views
from abs.cli.main import main
from abs.errors import InputError

SPEC = "charuco:7x5:30mm:22mm:DICT_5X5_100"
BOARD = parse_board(SPEC)
WIDTH, HEIGHT = 640, 480
# fx != fy and an off-centre principal point, so that a fit that ignored either would show.
K_TRUE = np.array([[600.0, 0, 322.6], [0, 604.0, 237.4], [0, 0, 1]])
DIST_TRUE = np.array([-0.12, 0.05, 0.0008, -0.001, 0.0])


def _to_uint8(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A rendered view with sensor noise (0.5 % of full scale), as an 8-bit photograph."""
    noisy = image + rng.normal(0, 0.005, image.shape)
    return np.clip(np.round(noisy * 255), 0, 255).astype(np.uint8)


def _hide_left_columns(image: np.ndarray, corners: np.ndarray, n_cols: int) -> np.ndarray:
    """Cover the board's first ``n_cols`` columns of inner corners with a grey card: a
    quadrilateral from the picture's left edge to halfway between corner columns ``n_cols - 1``
    and ``n_cols``."""
    cols, rows = BOARD.inner_corners
    grid = corners.reshape(rows, cols, 2)
    edge = 0.5 * (grid[:, n_cols - 1] + grid[:, n_cols])  # (rows, 2) the card's right edge
    top, bottom = edge[0] + 2 * (edge[0] - edge[1]), edge[-1] + 2 * (edge[-1] - edge[-2])
    card = np.array([[0, top[1] - 200], top, bottom, [0, bottom[1] + 200]], np.int32)
    hidden = image.copy()
    cv2.fillConvexPoly(hidden, card, 128)
    return hidden


@pytest.fixture(scope="module")
def photographs():
    """The synthetic views (truth) and their 8-bit photographs; view 7 partly covered."""
    rng = np.random.default_rng(7)
    views = board_views(BOARD, K_TRUE, DIST_TRUE, WIDTH, HEIGHT)
    images = [_to_uint8(im, rng) for im in board_images(BOARD, views, K_TRUE, DIST_TRUE, WIDTH,
                                                          HEIGHT, supersample=2)]
    images[7] = _hide_left_columns(images[7], views[7].corners, 3)
    return views, images


def test_parse_charuco():
    assert (BOARD.kind, BOARD.cols, BOARD.rows) == ("charuco", 7, 5)
    assert (BOARD.square_m, BOARD.marker_m) == pytest.approx((0.030, 0.022))
    assert BOARD.dictionary == "DICT_5X5_100" and BOARD.inner_corners == (6, 4)
    assert BOARD.spec == SPEC and parse_board(BOARD.spec) == BOARD
    other = parse_board("ChArUco:7x5:3cm:2.2cm:dict_5x5_100")  # case and units are free
    assert (other.kind, other.cols, other.rows, other.dictionary) == ("charuco", 7, 5, "DICT_5X5_100")
    assert (other.square_m, other.marker_m) == pytest.approx((0.030, 0.022))
    points = BOARD.object_points()
    # Inner corner (i, j) at (i s, j s): corner id 7 is column 1 of row 1.
    assert points.shape == (24, 3) and points[7].tolist() == pytest.approx([0.03, 0.03, 0.0])


@pytest.mark.parametrize("spec, words", [
    ("charuco:7x5:30mm", "charuco:COLSxROWS:SQUARE:MARKER:DICT"),
    ("charuco:7x5:30mm:22mm", "charuco:COLSxROWS:SQUARE:MARKER:DICT"),
    ("charuco:7by5:30mm:22mm:DICT_5X5_100", "'7by5' is not COLSxROWS (squares)"),
    ("charuco:7x5:30:22mm:DICT_5X5_100", "square size '30' is not a positive length"),
    ("charuco:7x5:30mm:0mm:DICT_5X5_100", "marker size '0mm' is not a positive length"),
    ("charuco:7x5:30mm:30mm:DICT_5X5_100", "the marker (30mm) must be smaller than the square"),
    ("charuco:2x5:30mm:22mm:DICT_5X5_100", "at least 3x3 squares"),
    ("charuco:7x5:30mm:22mm:DICT_9X9_1", "unknown ArUco dictionary 'DICT_9X9_1'"),
    ("charuco:15x15:30mm:22mm:DICT_4X4_50", "has 112 markers but DICT_4X4_50 only 50"),
])
def test_malformed_charuco_specs_name_the_field(spec, words):
    with pytest.raises(InputError) as info:
        parse_board(spec, source="rig.json", field="--board")
    assert info.value.field == "--board" and info.value.source == "rig.json"
    assert words in info.value.message, info.value.message


def test_calibration_recovers_the_known_camera(photographs):
    views, images = photographs
    corners = [detect_corners(image, BOARD) for image in images]
    assert all(c is not None for c in corners)
    errors = []
    for view, found in zip(views, corners):
        ids, pixels, _ = seen_points(found, BOARD.object_points())
        errors.append(pixels - view.corners[ids])
    errors = np.concatenate(errors)
    # OpenCV's ChArUco corners: 0.09 px RMS, 0.29 px worst measured on these views.
    assert np.sqrt(np.mean(np.sum(errors ** 2, axis=1))) < 0.15
    calib = calibrate_intrinsics(corners, BOARD.object_points(), WIDTH, HEIGHT)
    rel = np.array([calib.K[0, 0], calib.K[1, 1], calib.K[0, 2], calib.K[1, 2]]) \
        / K_TRUE[[0, 1, 0, 1], [0, 1, 2, 2]] - 1
    assert np.abs(rel).max() < 0.003, rel  # 0.11 % measured
    assert not calib.outliers and calib.rms_px < 0.15
    # The distortion's effect on pixel positions where the boards were seen, through the true K
    # (0.14 px measured; the whole model, K included, differs by up to 0.9 px there: the 0.1 %
    # of cx and cy is a third of a pixel, and the rest is tangential distortion traded for it).
    grid = np.stack(np.meshgrid(np.arange(WIDTH, dtype=np.float64),
                                np.arange(HEIGHT, dtype=np.float64)), -1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(grid, K_TRUE, DIST_TRUE, criteria=criteria).reshape(-1, 2)
    ours, _ = cv2.projectPoints(np.concatenate([rays, np.ones((len(rays), 1))], 1), np.zeros(3),
                                np.zeros(3), K_TRUE, calib.dist)
    err = np.linalg.norm(ours.reshape(-1, 2) - grid.reshape(-1, 2), axis=1)
    seen = coverage_map(corners, WIDTH, HEIGHT).ravel() > 0
    assert err[seen].max() < 0.25, f"max pixel-position error {err[seen].max():.3f} px"


def test_a_partly_hidden_board_still_gives_the_corners_it_shows(photographs):
    views, images = photographs
    found = detect_corners(images[7], BOARD)
    ids, pixels, _ = seen_points(found, BOARD.object_points())
    cols = BOARD.inner_corners[0]
    # The card hides corner columns 0..2 and the markers beside column 3 (8 corners found: a
    # ChArUco corner is only given where the markers around it are seen).
    assert set(ids % cols) <= {3, 4, 5} and 6 <= len(ids) < 24, ids
    assert np.abs(pixels - views[7].corners[ids]).max() < 0.5
    corners = [detect_corners(image, BOARD) for image in images]
    calib = calibrate_intrinsics(corners, BOARD.object_points(), WIDTH, HEIGHT,
                                 names=[f"v{k}" for k in range(len(images))])
    assert "v7" in calib.names and "v7" not in calib.outliers
    assert calib.view_rms_px[7] < 3 * np.median(calib.view_rms_px)
    # The partial view also places the camera (abs calibrate extrinsics): within a millimetre.
    R, t, rms = board_pose(found, BOARD.object_points(), K_TRUE, DIST_TRUE)
    assert np.linalg.norm(t - views[7].t) < 1e-3 and rms < 0.3
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(R @ views[7].R.T)[0])) < 0.2


def test_stereo_uses_the_corners_both_cameras_saw():
    """Stereo pairs of partial views: each pair is fitted with the corners both cameras saw."""
    rng = np.random.default_rng(11)
    obj = BOARD.object_points().astype(np.float64)
    R12 = cv2.Rodrigues(np.array([0.01, 0.05, -0.02]))[0]  # camera 1 -> camera 2
    T12 = np.array([-0.10, 0.002, 0.005])  # metres: a 10 cm baseline
    points1, points2 = [], []
    for k, view in enumerate(board_views(BOARD, K_TRUE, DIST_TRUE, WIDTH, HEIGHT)):
        seen2, _ = cv2.projectPoints(obj, cv2.Rodrigues(R12 @ view.R)[0], R12 @ view.t + T12,
                                     K_TRUE, DIST_TRUE)
        p1 = view.corners + rng.normal(0, 0.05, view.corners.shape)
        p2 = seen2.reshape(-1, 2) + rng.normal(0, 0.05, view.corners.shape)
        column = np.arange(len(obj)) % BOARD.inner_corners[0]
        p1[(column < 2) & (k % 2 == 0)] = np.nan  # camera 1 misses the left of every other board
        p2[(column > 3) & (k % 3 == 0)] = np.nan  # camera 2 the right of every third
        points1.append(p1)
        points2.append(p2)
    st = calibrate_stereo(points1, points2, obj, K_TRUE, DIST_TRUE, K_TRUE, DIST_TRUE, WIDTH,
                          HEIGHT)
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(st.R @ R12.T)[0])) < 0.05
    assert np.linalg.norm(st.T - T12) < 5e-4
    errors = epipolar_errors_px(points1[0], points2[0], st.F, K_TRUE, DIST_TRUE, K_TRUE, DIST_TRUE)
    assert len(errors) == 8 and errors.max() < 0.3  # columns 2 and 3 of 4 rows seen by both
    points2[0][4:] = np.nan
    with pytest.raises(InputError, match=r"pairs\[0\]: 2 corners seen by both cameras"):
        calibrate_stereo(points1, points2, obj, K_TRUE, DIST_TRUE, K_TRUE, DIST_TRUE, WIDTH,
                         HEIGHT)


def test_cli_calibrates_intrinsics_from_charuco_photographs(photographs, tmp_path):
    _, images = photographs
    paths = []
    for k, image in enumerate(images):
        paths.append(tmp_path / f"shot{k:02d}.png")
        cv2.imwrite(str(paths[-1]), image)
    out, report = tmp_path / "cams.json", tmp_path / "report"
    assert main(["calibrate", "intrinsics", *map(str, paths), "--board", SPEC, "--camera", "cam",
                 "--out", str(out), "--report", str(report)]) == 0
    cam = read_camera_file(out)["cam"]
    assert np.abs(np.diag(cam.K)[:2] / np.diag(K_TRUE)[:2] - 1).max() < 0.003
    assert (report / "cam_corners" / "shot07.png").is_file()  # the partial view, ids drawn
    assert json.loads((report / "report.json").read_text())["cam"]["not_found"] == []
