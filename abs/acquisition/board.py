"""Calibration boards: parsing ``checkerboard:9x6:25mm`` and finding their corners.

A board type is an entry of :data:`BOARD_TYPES` (a registry): adding one is adding a detector.
Board coordinates are metres in the board plane ``z = 0``; corner ``(i, j)`` (column i, row j of
the inner corners) is at ``(i * square_m, j * square_m, 0)``, in OpenCV's row-major detection
order, so the board defines a right-handed world frame with +z pointing into the board.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from abs.errors import InputError

__all__ = ["Board", "parse_board", "detect_corners", "BOARD_TYPES"]

_SPEC_RE = re.compile(r"(?P<kind>[a-z]+):(?P<cols>\d+)x(?P<rows>\d+):(?P<size>[0-9.]+)(?P<unit>mm|cm|m)")
_UNIT_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


@dataclass(frozen=True)
class Board:
    """A planar calibration board.

    Attributes
    ----------
    kind : str
        Key of :data:`BOARD_TYPES` (``"checkerboard"``).
    cols, rows : int
        Inner corners per row and per column (OpenCV's ``patternSize``).
    square_m : float
        Side of one square, metres.
    """

    kind: str
    cols: int
    rows: int
    square_m: float

    def object_points(self) -> np.ndarray:
        """``(cols * rows, 3)`` float32 corner positions on the board, metres, detection order."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        pts = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1) * self.square_m
        return pts.astype(np.float32)


def parse_board(spec: str, source: str | None = None, field: str = "board") -> Board:
    """Parse ``KIND:COLSxROWS:SIZE`` (e.g. ``checkerboard:9x6:25mm``; units mm, cm or m)."""
    match = _SPEC_RE.fullmatch(spec.strip().lower())
    if match is None:
        raise InputError(source, field, f"{spec!r} is not a board; expected KIND:COLSxROWS:SIZE "
                                        "such as checkerboard:9x6:25mm")
    kind = match["kind"]
    if kind not in BOARD_TYPES:
        raise InputError(source, field, f"unknown board type {kind!r}; known: "
                                        f"{', '.join(sorted(BOARD_TYPES))}")
    cols, rows = int(match["cols"]), int(match["rows"])
    square_m = float(match["size"]) * _UNIT_M[match["unit"]]
    if cols < 2 or rows < 2 or square_m <= 0:
        raise InputError(source, field, f"{spec!r}: need at least 2x2 inner corners and a "
                                        "positive square size")
    return Board(kind, cols, rows, square_m)


def _detect_checkerboard(gray: np.ndarray, board: Board) -> np.ndarray | None:
    """Inner corners with sub-pixel refinement (``cornerSubPix``), or ``None`` if not found."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, (board.cols, board.rows), flags=flags)
    if not found:
        return None
    # The refinement window's half-size is 0.4 corner spacings: large enough to average over the
    # edges (0.25 spacings left 0.9 px outlier views on the real 640x512 right camera), never
    # reaching the next corner on small images.
    corners = np.asarray(corners, np.float32).reshape(-1, 1, 2)
    spacing = float(np.median(np.linalg.norm(np.diff(corners[:, 0], axis=0), axis=1)))
    half = int(np.clip(0.4 * spacing, 2, 15))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    corners = cv2.cornerSubPix(gray, corners, (half, half), (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(np.float32)


#: Board kind -> detector ``(gray uint8 image, Board) -> (N, 2) pixel corners or None``.
BOARD_TYPES: dict[str, Callable[[np.ndarray, Board], np.ndarray | None]] = {
    "checkerboard": _detect_checkerboard,
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
        ``(cols * rows, 2)`` float32 pixel positions (pixel centres at integers, as in
        docs/conventions.md) in :meth:`Board.object_points` order, or ``None`` if not found.
    """
    gray = np.asarray(image)
    if gray.ndim == 3:
        gray = gray.mean(axis=2)
    if gray.dtype != np.uint8:
        gray = np.clip(np.asarray(gray, np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return BOARD_TYPES[board.kind](gray, board)
