"""Synthetic calibration data with known truth: board poses, their projected corners, pictures.

A calibration is only as good as its views. Before photographing a board, or to check that a
pipeline recovers a known camera, :func:`board_views` gives a standard set of views of a board
through a known camera (K and Brown-Conrady distortion): a 3 x 3 grid of positions over the
image, each seen at two tilts, with the exact pixel position of every corner. Those are the views
of tests/test_acquisition_calibration.py, tests/test_acquisition_charuco.py and
``benchmarks/acquisition.py``'s synthetic calibration;
:func:`calibrate_intrinsics <abs.acquisition.intrinsics.calibrate_intrinsics>` on them (with
0.03 px of corner noise) recovers K within 0.5 %. :func:`board_images` draws the board's picture
into those views (exact geometry, supersampled, no noise), for testing detection as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from abs.acquisition.board import Board

__all__ = ["BoardView", "board_views", "board_images"]


@dataclass(frozen=True)
class BoardView:
    """One synthetic view of a board.

    Attributes
    ----------
    R : np.ndarray
        (3, 3) rotation, board frame -> OpenCV camera frame (x right, y down, z forward).
    t : np.ndarray
        (3,) translation, metres: the board origin in the camera frame.
    corners : np.ndarray
        ``(N, 2)`` exact pixel positions (pixel centres at integers) of
        :meth:`Board.object_points <abs.acquisition.board.Board.object_points>`, distortion
        included.
    """

    R: np.ndarray
    t: np.ndarray
    corners: np.ndarray

    @property
    def rvec(self) -> np.ndarray:
        """(3,) the rotation as an OpenCV rotation vector, radians."""
        return cv2.Rodrigues(self.R)[0].ravel()


def board_views(board: Board, K: np.ndarray, dist: np.ndarray, width: int, height: int,
                distance_m: float = 0.45, tilt_rad: float = 0.4, spread: float = 0.234,
                margin_px: float = 1.0) -> list[BoardView]:
    """Views of ``board`` centred on a 3 x 3 grid of image positions, two tilts each.

    The board's centre sits on the ray through each grid position, ``distance_m`` along the
    optical axis, turned by ``+tilt_rad`` and ``-tilt_rad`` about both board axes (with a varying
    roll), as a hand-held board is. Views whose corners leave the image are dropped, as a
    detector would drop them, so fewer than 18 views come back when the board is large in the
    image.

    Parameters
    ----------
    board : Board
        The board; its :meth:`~abs.acquisition.board.Board.object_points` are projected.
    K : np.ndarray
        (3, 3) camera matrix, pixels.
    dist : np.ndarray
        OpenCV distortion coefficients (``k1, k2, p1, p2, k3``, ...), dimensionless.
    width, height : int
        Image size, pixels.
    distance_m : float
        Depth of the board's centre, metres.
    tilt_rad : float
        Tilt of the board about its axes, radians.
    spread : float
        Spacing of the grid positions, as a fraction of the image width and height (rounded to
        whole pixels; 0.234 puts them 75 px apart on a 320 px wide image).
    margin_px : float
        Every corner must lie at least this far inside the image, pixels.

    Returns
    -------
    list of BoardView
        In grid order (rows top to bottom, positions left to right, the two tilts in turn).
    """
    obj = board.object_points().astype(np.float64)
    centre = obj.mean(axis=0)
    K = np.asarray(K, np.float64)
    dist = np.asarray(dist, np.float64)
    step_u, step_v = round(spread * width), round(spread * height)
    views, k = [], 0
    for v in (height / 2 - step_v, height / 2, height / 2 + step_v):
        for u in (width / 2 - step_u, width / 2, width / 2 + step_u):
            for tilt in (tilt_rad, -tilt_rad):
                k += 1
                # Tilt about x alternates in three steps and roll in four, so that no two views
                # share a rotation: each constrains the focal length and distortion differently.
                rvec = np.array([tilt * (k % 3 - 1) + 0.1, tilt, 0.15 * (k % 4 - 1.5)])
                R = cv2.Rodrigues(rvec)[0]
                t = distance_m * np.linalg.solve(K, [u, v, 1.0]) - R @ centre
                p, _ = cv2.projectPoints(obj, rvec, t, K, dist)
                p = p.reshape(-1, 2)
                if (p.min() >= margin_px and p[:, 0].max() <= width - 1 - margin_px
                        and p[:, 1].max() <= height - 1 - margin_px):
                    views.append(BoardView(R, t, p))
    return views


def _fine_rays(K: np.ndarray, dist: np.ndarray, width: int, height: int,
               supersample: int) -> np.ndarray:
    """Normalised pinhole coordinates ``(x/z, y/z)`` of the centres of a ``supersample`` times
    finer pixel grid of the distorted image, ``(height * n, width * n, 2)``."""
    n = supersample
    # Fine pixel centres in coarse pixel units (coarse centres at integers).
    xs = (np.arange(width * n) - (n - 1) / 2) / n
    ys = (np.arange(height * n) - (n - 1) / 2) / n
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 1, 2)
    # undistortPoints inverts the distortion iteratively; its default 5 iterations leave errors
    # of hundredths of a pixel at the image corners, more than the corner accuracy being tested.
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    rays = cv2.undistortPoints(grid, np.asarray(K, np.float64), np.asarray(dist, np.float64),
                               criteria=criteria)
    return rays.reshape(height * n, width * n, 2)


def board_images(board: Board, views: list[BoardView], K: np.ndarray, dist: np.ndarray,
                 width: int, height: int, supersample: int = 3, square_px: int = 100,
                 black: float = 0.05, white: float = 0.85) -> list[np.ndarray]:
    """Pictures of ``board`` (:meth:`Board.image <abs.acquisition.board.Board.image>`) seen in
    ``views`` through the camera ``K``, ``dist``: exact geometry, no noise.

    Each image pixel averages ``supersample`` x ``supersample`` point samples (as a sensor
    pixel integrates light), each a bilinear look-up of the board picture where the sample's
    ray meets the board plane; outside the picture (and the one-square white margin around the
    board) is white.

    Parameters
    ----------
    board : Board
        The board.
    views : list of BoardView
        Its poses (:func:`board_views`).
    K, dist : np.ndarray
        The camera: (3, 3) matrix, pixels; OpenCV distortion coefficients.
    width, height : int
        Image size, pixels.
    supersample : int
        Samples per pixel along each axis.
    square_px : int
        Resolution of the board picture, pixels per square: fine enough that its own pixels are
        much smaller than an image sample.
    black, white : float
        Image values of the board's black and white, linear in [0, 1].

    Returns
    -------
    list of np.ndarray
        Per view, ``(height, width)`` float32 in [0, 1].
    """
    picture = board.image(square_px).astype(np.float32) / 255.0
    # Board metres -> picture pixel centres: the origin (first inner corner) lies two squares in
    # (the margin and the first square) from the picture's pixel edges.
    origin = 2 * square_px - 0.5
    scale = square_px / board.square_m
    rays = _fine_rays(K, dist, width, height, supersample)
    homogeneous = np.concatenate([rays, np.ones(rays.shape[:2] + (1,))], axis=-1)
    out = []
    for view in views:
        # A ray meets the plane z = 0 of the board where [x, y, 1] ~ [r1 r2 t] [X, Y, 1].
        to_board = np.linalg.inv(np.column_stack([view.R[:, 0], view.R[:, 1], view.t]))
        board_xy = homogeneous @ to_board.T
        board_xy = board_xy[..., :2] / board_xy[..., 2:]
        map_x = (origin + scale * board_xy[..., 0]).astype(np.float32)
        map_y = (origin + scale * board_xy[..., 1]).astype(np.float32)
        fine = cv2.remap(picture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=1.0)
        image = cv2.resize(fine, (width, height), interpolation=cv2.INTER_AREA)
        out.append((black + (white - black) * image).astype(np.float32))
    return out
