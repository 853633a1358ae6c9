"""Calibration boards: parsing ``checkerboard:9x6:25mm`` or ``charuco:7x5:30mm:22mm:DICT_5X5_100``
and finding their corners.

A board type is an entry of :data:`BOARD_TYPES` (a registry): adding one is adding a detector.
Board coordinates are metres in the board plane ``z = 0``; inner corner ``(i, j)`` (column i, row
j of the inner corners) is at ``(i * square_m, j * square_m, 0)``, in OpenCV's row-major detection
order, so the board defines a right-handed world frame with +z pointing into the board. Both
kinds share this frame: for a ChArUco board, inner corner ``(i, j)`` is OpenCV's ChArUco corner
id ``j * (cols - 1) + i`` (OpenCV puts its origin one square further out, at the board's edge).

Detection gives every inner corner of the board, in :meth:`Board.object_points` order; a corner
that was not seen is a row of NaN. A checkerboard is found whole or not at all; a ChArUco board's
markers identify each corner, so a partly hidden or partly out-of-frame board still gives the
corners it shows (:func:`seen_points` picks them, with their board positions).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["Board", "parse_board", "detect_corners", "seen_points", "BOARD_TYPES",
           "MIN_CHARUCO_CORNERS"]

_GRID_RE = re.compile(r"(?P<cols>\d+)x(?P<rows>\d+)")
_SIZE_RE = re.compile(r"(?P<size>[0-9]*\.?[0-9]+)(?P<unit>mm|cm|m)")
_UNIT_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
#: The form of each kind's specification, for error messages.
_SYNTAX = {"checkerboard": "checkerboard:COLSxROWS:SIZE (inner corners, e.g. "
                           "checkerboard:9x6:25mm)",
           "charuco": "charuco:COLSxROWS:SQUARE:MARKER:DICT (squares, e.g. "
                      "charuco:7x5:30mm:22mm:DICT_5X5_100)"}
#: Fewest ChArUco corners a view must show to be used. Six, not the four a homography needs:
#: with four, one wrong corner cannot be told apart from the rest in the view's residuals.
MIN_CHARUCO_CORNERS = 6


@dataclass(frozen=True)
class Board:
    """A planar calibration board.

    Attributes
    ----------
    kind : str
        Key of :data:`BOARD_TYPES` (``"checkerboard"`` or ``"charuco"``).
    cols, rows : int
        Checkerboard: inner corners per row and per column (OpenCV's ``patternSize``). ChArUco:
        squares per row and per column (OpenCV's ``CharucoBoard`` size); its inner corners are
        ``(cols - 1) x (rows - 1)``.
    square_m : float
        Side of one square, metres.
    marker_m : float or None
        ChArUco: side of one ArUco marker, metres (smaller than ``square_m``); else ``None``.
    dictionary : str or None
        ChArUco: the OpenCV ArUco dictionary, e.g. ``"DICT_5X5_100"``; else ``None``.
    """

    kind: str
    cols: int
    rows: int
    square_m: float
    marker_m: float | None = None
    dictionary: str | None = None

    @property
    def inner_corners(self) -> tuple[int, int]:
        """``(columns, rows)`` of inner corners: the grid :meth:`object_points` spans."""
        if self.kind == "charuco":
            return self.cols - 1, self.rows - 1
        return self.cols, self.rows

    @property
    def spec(self) -> str:
        """The board as ``--board`` writes it (sizes in mm)."""
        grid = f"{self.kind}:{self.cols}x{self.rows}:{self.square_m * 1e3:g}mm"
        if self.kind == "charuco":
            return f"{grid}:{self.marker_m * 1e3:g}mm:{self.dictionary}"
        return grid

    def object_points(self) -> np.ndarray:
        """``(n, 3)`` float32 inner-corner positions on the board, metres, detection order."""
        cols, rows = self.inner_corners
        j, i = np.mgrid[0:rows, 0:cols]
        pts = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1) * self.square_m
        return pts.astype(np.float32)

    def image(self, square_px: int, margin_px: int | None = None) -> np.ndarray:
        """The board as a uint8 picture (black 0, white 255), to print or to render.

        Parameters
        ----------
        square_px : int
            Side of one square, pixels.
        margin_px : int, optional
            White margin around the board, pixels (default one square).

        Returns
        -------
        np.ndarray
            ``(H, W)`` uint8. The first inner corner, the board origin, lies
            ``margin_px + square_px`` pixels from the top and left edges of the picture (pixel
            edges, not centres), x along the columns and y down the rows.
        """
        margin = square_px if margin_px is None else margin_px
        # Squares, not inner corners: a checkerboard of n inner corners has n + 1 squares.
        n_cols, n_rows = (self.cols, self.rows) if self.kind == "charuco" else \
            (self.cols + 1, self.rows + 1)
        size = (n_cols * square_px + 2 * margin, n_rows * square_px + 2 * margin)
        if self.kind == "charuco":
            return _charuco(self).generateImage(size, marginSize=margin, borderBits=1)
        picture = np.full((size[1], size[0]), 255, np.uint8)
        for r in range(n_rows):
            for c in range(n_cols):
                if (r + c) % 2 == 0:
                    y0, x0 = margin + r * square_px, margin + c * square_px
                    picture[y0:y0 + square_px, x0:x0 + square_px] = 0
        return picture


def _parse_size(text: str, spec: str, source: str | None, field: str, what: str) -> float:
    """A length such as ``25mm``, metres."""
    match = _SIZE_RE.fullmatch(text.strip().lower())
    if match is None or float(match["size"]) <= 0:
        raise InputError(source, field, f"{spec!r}: {what} {text!r} is not a positive length "
                                        "with a unit (mm, cm or m), e.g. 25mm")
    return float(match["size"]) * _UNIT_M[match["unit"]]


def _parse_grid(text: str, spec: str, source: str | None, field: str,
                what: str) -> tuple[int, int]:
    match = _GRID_RE.fullmatch(text.strip().lower())
    if match is None:
        raise InputError(source, field, f"{spec!r}: {text!r} is not COLSxROWS ({what}), e.g. 9x6")
    return int(match["cols"]), int(match["rows"])


def _dictionary_size(name: str) -> int | None:
    """Markers in OpenCV's predefined ArUco dictionary ``name``, or ``None`` if there is none."""
    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        return None
    return int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0])


def parse_board(spec: str, source: str | None = None, field: str = "board") -> Board:
    """Parse a board specification.

    ``checkerboard:COLSxROWS:SIZE`` counts inner corners (``checkerboard:9x6:25mm``);
    ``charuco:COLSxROWS:SQUARE:MARKER:DICT`` counts squares and gives the square and marker sizes
    and OpenCV's ArUco dictionary (``charuco:7x5:30mm:22mm:DICT_5X5_100``). Sizes are in mm, cm
    or m.

    Raises
    ------
    InputError
        Naming ``source`` and ``field`` and the part of ``spec`` that is wrong.
    """
    parts = spec.strip().split(":")
    kind = parts[0].strip().lower()
    if len(parts) < 3:
        raise InputError(source, field, f"{spec!r} is not a board; expected KIND:COLSxROWS:SIZE "
                                        "such as checkerboard:9x6:25mm (or charuco:COLSxROWS:"
                                        "SQUARE:MARKER:DICT)")
    if kind not in BOARD_TYPES:
        raise InputError(source, field, f"unknown board type {kind!r}; known: "
                                        f"{', '.join(sorted(BOARD_TYPES))}")
    expected = 5 if kind == "charuco" else 3
    if len(parts) != expected:
        syntax = _SYNTAX.get(kind, _SYNTAX["checkerboard"])
        raise InputError(source, field, f"{spec!r}: expected {syntax}")
    if kind == "charuco":
        return _parse_charuco(parts, spec, source, field)
    cols, rows = _parse_grid(parts[1], spec, source, field, "inner corners")
    square_m = _parse_size(parts[2], spec, source, field, "square size")
    if cols < 2 or rows < 2:
        raise InputError(source, field, f"{spec!r}: need at least 2x2 inner corners")
    return Board(kind, cols, rows, square_m)


def _parse_charuco(parts: list[str], spec: str, source: str | None, field: str) -> Board:
    """``charuco:COLSxROWS:SQUARE:MARKER:DICT`` split at the colons (five parts)."""
    cols, rows = _parse_grid(parts[1], spec, source, field, "squares")
    square_m = _parse_size(parts[2], spec, source, field, "square size")
    marker_m = _parse_size(parts[3], spec, source, field, "marker size")
    if cols < 3 or rows < 3:
        raise InputError(source, field, f"{spec!r}: need at least 3x3 squares (2x2 inner "
                                        "corners)")
    if marker_m >= square_m:
        raise InputError(source, field, f"{spec!r}: the marker ({parts[3]}) must be smaller than "
                                        f"the square ({parts[2]})")
    dictionary = parts[4].strip().upper()
    n_markers = _dictionary_size(dictionary)
    if n_markers is None:
        raise InputError(source, field, f"{spec!r}: unknown ArUco dictionary {parts[4]!r}; "
                                        "expected an OpenCV name such as DICT_4X4_50, "
                                        "DICT_5X5_100, DICT_6X6_250 or DICT_APRILTAG_36H11")
    # Markers sit on the white squares: half of them, rounded down.
    if cols * rows // 2 > n_markers:
        raise InputError(source, field, f"{spec!r}: a {cols}x{rows} board has "
                                        f"{cols * rows // 2} markers but {dictionary} only "
                                        f"{n_markers}; take a larger dictionary")
    return Board("charuco", cols, rows, square_m, marker_m, dictionary)


def _detect_checkerboard(gray: np.ndarray, board: Board) -> np.ndarray | None:
    """Inner corners with sub-pixel refinement (``cornerSubPix``), or ``None`` if not found."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, (board.cols, board.rows), flags=flags)
    if not found:
        return None
    corners = np.asarray(corners, np.float32).reshape(-1, 2)
    spacing = float(np.median(np.linalg.norm(np.diff(corners, axis=0), axis=1)))
    return _refine(gray, corners, spacing)


@functools.lru_cache(maxsize=8)
def _charuco(board: Board) -> cv2.aruco.CharucoBoard:
    """OpenCV's board object (cached: a calibration detects the same board in every image)."""
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    return cv2.aruco.CharucoBoard((board.cols, board.rows), board.square_m, board.marker_m,
                                  dictionary)


def _detect_charuco(gray: np.ndarray, board: Board) -> np.ndarray | None:
    """ChArUco corners seen (the others NaN), or ``None`` if fewer than
    :data:`MIN_CHARUCO_CORNERS` or all on one line (no homography, so no calibration)."""
    cv_board = _charuco(board)
    detector = cv2.aruco.CharucoDetector(cv_board)
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
        return None
    ids = np.asarray(ids, np.int32).ravel()
    if cv_board.checkCharucoCornersCollinear(ids.reshape(-1, 1)):
        return None
    # detectBoard interpolates the corners from the markers and already refines each with
    # cornerSubPix, in a window sized per corner to stay clear of the nearest marker. The
    # checkerboard's window (0.4 squares) is not used here: it reaches the markers, whose edges
    # pull the corners off by pixels.
    found = np.full((len(board.object_points()), 2), np.nan, np.float32)
    found[ids] = np.asarray(corners, np.float32).reshape(-1, 2)
    return found


def _refine(gray: np.ndarray, corners: np.ndarray, spacing: float) -> np.ndarray:
    """Sub-pixel corners (``cornerSubPix``), ``(n, 2)`` float32.

    The refinement window's half-size is 0.4 corner spacings: large enough to average over the
    edges (0.25 spacings left 0.9 px outlier views on the real 640x512 right camera), never
    reaching the next corner on small images.
    """
    half = int(np.clip(0.4 * spacing, 2, 15))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    corners = cv2.cornerSubPix(gray, corners.reshape(-1, 1, 2).astype(np.float32), (half, half),
                               (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(np.float32)


#: Board kind -> detector ``(gray uint8 image, Board) -> (n, 2) pixel corners or None``.
BOARD_TYPES: dict[str, Callable[[np.ndarray, Board], np.ndarray | None]] = {
    "checkerboard": _detect_checkerboard,
    "charuco": _detect_charuco,
}


def detect_corners(image: np.ndarray, board: Board) -> np.ndarray | None:
    """Find the board's inner corners in one image.

    Parameters
    ----------
    image : np.ndarray
        ``(H, W)`` or ``(H, W, 3)`` image, uint8 or float in [0, 1].
    board : Board
        The board to look for.

    Returns
    -------
    np.ndarray or None
        ``(n, 2)`` float32 pixel positions (pixel centres at integers, as in
        docs/conventions.md) in :meth:`Board.object_points` order, NaN for corners not seen (a
        partly hidden ChArUco board), or ``None`` if the board was not found.
    """
    gray = np.asarray(image)
    if gray.ndim == 3:
        gray = gray.mean(axis=2)
    if gray.dtype != np.uint8:
        gray = np.clip(np.asarray(gray, np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return BOARD_TYPES[board.kind](gray, board)


def seen_points(corners: np.ndarray,
                object_points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The corners a view shows, with their positions on the board.

    Parameters
    ----------
    corners : np.ndarray
        ``(n, 2)`` detected corners, pixels, NaN where not seen (:func:`detect_corners`).
    object_points : np.ndarray
        ``(n, 3)`` the board's corners, metres (:meth:`Board.object_points`).

    Returns
    -------
    ids : np.ndarray
        ``(m,)`` int indices of the seen corners (ChArUco corner ids).
    image_points : np.ndarray
        ``(m, 2)`` their pixel positions.
    board_points : np.ndarray
        ``(m, 3)`` their board positions, metres.

    Raises
    ------
    InputError
        If ``corners`` and ``object_points`` differ in length.
    """
    corners = np.asarray(corners).reshape(-1, 2)
    object_points = np.asarray(object_points)
    if len(corners) != len(object_points):
        raise InputError(None, "corners", f"{len(corners)} corners for {len(object_points)} "
                                          "board points")
    ids = np.flatnonzero(np.all(np.isfinite(corners), axis=1))
    return ids, corners[ids], object_points[ids]
