"""Board detection, intrinsic and stereo calibration, distortion and undistortion.

Synthetic checks use boards drawn with a known homography and corners projected with known K and
distortion; real checks use ../shared/data/stereo_chessboard_640x512 (skipped when absent).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from abs.acquisition.board import Board, detect_corners, parse_board
from abs.acquisition.camera_file import CameraModel, read_camera_file, write_camera_file
from abs.acquisition.detection import detect_in_files
from abs.acquisition.intrinsics import calibrate_intrinsics, coverage_map
from abs.acquisition.stereo import calibrate_stereo, epipolar_errors_px
from abs.acquisition.synthetic import board_images, board_views
from abs.acquisition.undistort import pinhole_K, undistort_image
from abs.errors import InputError
from abs.io.shared_data import shared_data_dir

STEREO = shared_data_dir() / "stereo_chessboard_640x512"
BOARD = Board("checkerboard", 9, 6, 0.025)
K_TRUE = np.array([[300.0, 0, 161.3], [0, 302.0, 118.7], [0, 0, 1]])
DIST_TRUE = np.array([-0.21, 0.09, 0.001, -0.0015, 0.0])


def _board_image(H: np.ndarray, size=(320, 240), square_px=40, supersample=4) -> np.ndarray:
    """A 10x7-square chessboard (9x6 inner corners) with a white margin, warped by H.

    Drawn ``supersample`` times larger and area-averaged down, as a lens integrates over a pixel.
    """
    pattern = BOARD.image(square_px)
    # cv2 maps pixel centres; corner (i, j) of the inner grid is at ((i+2)*s - 0.5, (j+2)*s - 0.5).
    n = supersample
    # Pixel centres: x_big = n * x + (n - 1) / 2, so the large image's homography is A @ H @ ...
    A = np.array([[n, 0, (n - 1) / 2], [0, n, (n - 1) / 2], [0, 0, 1]])
    big = cv2.warpPerspective(pattern.astype(np.float32), A @ H, (size[0] * n, size[1] * n),
                              flags=cv2.INTER_LINEAR, borderValue=255)
    small = cv2.resize(big, size, interpolation=cv2.INTER_AREA)
    return np.clip(small + 0.5, 0, 255).astype(np.uint8)


def test_parse_board_and_bad_specs():
    board = parse_board("checkerboard:9x6:25mm")
    assert (board.cols, board.rows) == (9, 6) and board.square_m == pytest.approx(0.025)
    assert board.object_points()[10].tolist() == pytest.approx([0.025, 0.025, 0.0])
    with pytest.raises(InputError, match="unknown board type 'chess'"):
        parse_board("chess:9x6:25mm")
    with pytest.raises(InputError, match="KIND:COLSxROWS:SIZE"):
        parse_board("checkerboard:9x6")


def test_corner_detection_is_subpixel_accurate():
    s = 40
    H = np.array([[0.55, 0.08, 30.0], [-0.05, 0.5, 25.0], [0.0002, 0.0001, 1.0]])
    image = _board_image(H, square_px=s)
    corners = detect_corners(image, BOARD)
    assert corners is not None
    j, i = np.mgrid[0:6, 0:9]
    src = np.stack([(i.ravel() + 2) * s - 0.5, (j.ravel() + 2) * s - 0.5], 1).astype(np.float64)
    truth = cv2.perspectiveTransform(src.reshape(-1, 1, 2), H).reshape(-1, 2)
    # Detection order may start at either end of the board; compare to the nearer ordering.
    err = min(np.abs(corners - truth).max(), np.abs(corners[::-1] - truth).max())
    assert err < 0.1, f"max corner error {err:.3f} px"


def _board_views(noise_px: float, rng: np.random.Generator) -> list[np.ndarray]:
    """Corners of the board at the 18 poses of :func:`abs.acquisition.synthetic.board_views`
    through K_TRUE and DIST_TRUE, with Gaussian detection noise."""
    return [v.corners + rng.normal(0, noise_px, v.corners.shape)
            for v in board_views(BOARD, K_TRUE, DIST_TRUE, 320, 240)]


def test_synthetic_board_images_put_the_corners_where_the_views_say():
    """abs.acquisition.synthetic.board_images draws the board where board_views projects it."""
    views = board_views(BOARD, K_TRUE, DIST_TRUE, 320, 240)[::6]
    for view, image in zip(views, board_images(BOARD, views, K_TRUE, DIST_TRUE, 320, 240)):
        corners = detect_corners(image, BOARD)
        assert corners is not None
        err = np.linalg.norm(corners - view.corners, axis=1)
        # Measured: RMS 0.05 to 0.07 px, worst 0.16 px (a corner foreshortened to 8 px squares).
        assert np.sqrt(np.mean(err ** 2)) < 0.1 and err.max() < 0.25


def test_intrinsics_recover_known_camera_and_flag_outlier():
    rng = np.random.default_rng(3)
    obj = BOARD.object_points().astype(np.float64)
    points = _board_views(0.03, rng)
    assert len(points) == 18
    bad = list(points)
    bad[4] = bad[4] + rng.normal(0, 1.0, bad[4].shape)  # one blurred / mis-detected view
    calib = calibrate_intrinsics(bad, obj, 320, 240)
    assert list(calib.outliers) == ["view4"] and "median" in calib.outliers["view4"]
    calib = calibrate_intrinsics(points, obj, 320, 240)
    rel = np.abs(np.array([calib.K[0, 0], calib.K[1, 1], calib.K[0, 2], calib.K[1, 2]])
                 / K_TRUE[[0, 1, 0, 1], [0, 1, 2, 2]] - 1)
    assert rel.max() < 0.005, rel
    assert calib.rms_px == pytest.approx(0.03 * np.sqrt(2), rel=0.3)
    # Distortion's effect on pixel positions at every pixel, against the truth: where the boards
    # were seen (< 0.1 px; 0.078 measured) and out in the image corners no board reached, an
    # extrapolation (< 0.25 px; 0.164 measured).
    grid = np.stack(np.meshgrid(np.arange(320.0), np.arange(240.0)), -1).reshape(-1, 2)
    rays = cv2.undistortPoints(grid.reshape(-1, 1, 2), K_TRUE, DIST_TRUE).reshape(-1, 2)
    pts3 = np.concatenate([rays, np.ones((len(rays), 1))], 1)
    ours, _ = cv2.projectPoints(pts3, np.zeros(3), np.zeros(3), calib.K, calib.dist)
    err = np.linalg.norm(ours.reshape(-1, 2) - grid, axis=1)
    seen = coverage_map(points, 320, 240).ravel() > 0
    assert err[seen].max() < 0.1, f"max pixel-position error {err[seen].max():.3f} px"
    assert err.max() < 0.25, f"max pixel-position error {err.max():.3f} px"
    assert 0 < calib.std["fx"] < 1.0 and calib.std["k1"] > 0


def test_too_few_views_is_an_error():
    obj = BOARD.object_points()
    with pytest.raises(InputError, match="at least 3"):
        calibrate_intrinsics([obj[:, :2]] * 2, obj, 320, 240)


def test_undistortion_moves_points_to_the_pinhole_projection():
    cam = CameraModel(320, 240, K_TRUE, DIST_TRUE)
    K_new = pinhole_K(cam)
    assert K_new[0, 2] != K_TRUE[0, 2]  # the principal point moves with undistortion
    X = np.array([[0.05, -0.03, 0.4], [-0.1, 0.06, 0.5], [0.12, 0.1, 0.45]])
    distorted, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K_TRUE, DIST_TRUE)
    pinhole = (K_new @ (X / X[:, 2:]).T).T[:, :2]
    v, u = np.mgrid[0:240, 0:320]
    image = np.zeros((240, 320), np.float32)
    for x, y in distorted.reshape(-1, 2):
        image += np.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * 1.5 ** 2))
    out = undistort_image(image, cam, K_new)
    for x, y in pinhole:
        ys, xs = slice(int(y) - 6, int(y) + 7), slice(int(x) - 6, int(x) + 7)
        w = out[ys, xs]
        cx = (w * u[ys, xs]).sum() / w.sum()
        cy = (w * v[ys, xs]).sum() / w.sum()
        assert np.hypot(cx - x, cy - y) < 0.15, (cx, cy, x, y)


def test_camera_file_round_trip_and_errors(tmp_path: Path):
    path = tmp_path / "cams.json"
    write_camera_file(path, {"left": CameraModel(320, 240, K_TRUE, DIST_TRUE, rms_px=0.1)})
    cam = read_camera_file(path)["left"]
    np.testing.assert_allclose(cam.K, K_TRUE)
    np.testing.assert_allclose(cam.distortion, DIST_TRUE)
    text = path.read_text().replace('"width": 320', '"width": -1')
    path.write_text(text)
    with pytest.raises(InputError, match=r"cams.json: cameras.left.width"):
        read_camera_file(path)


def test_board_not_found_and_mixed_sizes(tmp_path: Path):
    blank = np.full((48, 64), 200, np.uint8)
    cv2.imwrite(str(tmp_path / "a.png"), blank)
    cv2.imwrite(str(tmp_path / "b.png"), blank)
    cv2.imwrite(str(tmp_path / "c.png"), np.full((40, 64), 200, np.uint8))
    with pytest.raises(InputError, match="not found in any of the 2 images"):
        detect_in_files([tmp_path / "a.png", tmp_path / "b.png"], BOARD)
    with pytest.raises(InputError, match=r"c.png: image is 64x40 pixels but a.png is 64x48"):
        detect_in_files([tmp_path / "a.png", tmp_path / "c.png"], BOARD)


@pytest.mark.skipif(not STEREO.is_dir(), reason=f"shared data absent: {STEREO}")
def test_real_stereo_pairs_against_reference():
    left = detect_in_files(sorted(STEREO.glob("left*.jpg")), BOARD)
    right = detect_in_files(sorted(STEREO.glob("right*.jpg")), BOARD)
    assert len(left.found) == 25 and len(right.found) == 25
    obj = BOARD.object_points()
    cl = calibrate_intrinsics(left.corners, obj, 640, 512)
    cr = calibrate_intrinsics(right.corners, obj, 640, 512)
    # OpenCV's own run on these images reports 0.149 px (left) and 0.161 px (right).
    assert cl.rms_px < 0.2 and cr.rms_px < 0.2
    ref = cv2.FileStorage(str(STEREO / "reference_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    for calib, key in ((cl, "M1"), (cr, "M2")):
        M = ref.getNode(key).mat()
        assert abs(calib.K[0, 0] / M[0, 0] - 1) < 0.01
        assert np.hypot(*(calib.K[:2, 2] - M[:2, 2])) < 5.0
    train, held = list(range(20)), list(range(20, 25))
    st = calibrate_stereo([left.corners[i] for i in train], [right.corners[i] for i in train],
                          obj, cl.K, cl.dist, cr.K, cr.dist, 640, 512)
    errs = np.concatenate([epipolar_errors_px(left.corners[i], right.corners[i], st.F, cl.K,
                                              cl.dist, cr.K, cr.dist) for i in held])
    assert np.sqrt(np.mean(errs ** 2)) < 0.5
    ref_extrinsics = cv2.FileStorage(str(STEREO / "reference_extrinsics.yml"),
                                     cv2.FILE_STORAGE_READ)
    R_ref = ref_extrinsics.getNode("R").mat()
    angle = np.degrees(np.linalg.norm(cv2.Rodrigues(st.R @ R_ref.T)[0]))
    assert angle < 1.0


def test_stereo_images_of_different_sizes_refused(tmp_path: Path, capsys):
    from abs.cli.main import main

    H = np.array([[0.55, 0.08, 30.0], [-0.05, 0.5, 25.0], [0.0002, 0.0001, 1.0]])
    cv2.imwrite(str(tmp_path / "left.png"), _board_image(H))
    cv2.imwrite(str(tmp_path / "right.png"), _board_image(H, size=(320, 236)))
    code = main(["calibrate", "stereo", "--left", str(tmp_path / "left.png"), "--right",
                 str(tmp_path / "right.png"), "--board", "checkerboard:9x6:25mm",
                 "--out", str(tmp_path / "cams.json")])
    assert code == 2
    assert "right.png: image size 320x236 differs from left's 320x240" in capsys.readouterr().err
