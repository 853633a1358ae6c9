"""Finding a board in a set of image files (sizes checked, failures reported per file)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from abs.acquisition.board import Board, detect_corners
from abs.errors import InputError

__all__ = ["Detections", "detect_in_files", "read_gray"]


@dataclass
class Detections:
    """Board corners found in a list of image files.

    Attributes
    ----------
    paths : list of Path
        All images, in order.
    corners : list of (np.ndarray or None)
        Per image, ``(N, 2)`` pixel corners, or ``None`` where the board was not found.
    width, height : int
        The common image size, pixels.
    """

    paths: list[Path]
    corners: list[np.ndarray | None]
    width: int
    height: int

    @property
    def found(self) -> list[int]:
        """Indices of the images where the board was found."""
        return [i for i, c in enumerate(self.corners) if c is not None]


def read_gray(path: str | Path) -> np.ndarray:
    """An image file as ``(H, W)`` uint8 grey (8- or 16-bit files; for detection only)."""
    pixels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise InputError(path, "", "cannot read this image (missing file or unknown format)")
    if pixels.ndim == 3:
        pixels = cv2.cvtColor(pixels[..., :3], cv2.COLOR_BGR2GRAY)
    if pixels.dtype != np.uint8:
        scale = 255.0 / max(float(pixels.max()), 1e-12)
        pixels = np.clip(pixels.astype(np.float64) * scale, 0, 255).astype(np.uint8)
    return pixels


def detect_in_files(paths: Sequence[str | Path], board: Board,
                    progress: Callable[[int], None] | None = None) -> Detections:
    """Detect ``board`` in every image; all images must share one size.

    Raises
    ------
    InputError
        Naming the first image whose size differs from the first image's, or, when the board is
        found in no image, naming the images searched.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError(None, "images", "no images given")
    corners: list[np.ndarray | None] = []
    size: tuple[int, int] | None = None
    for path in paths:
        gray = read_gray(path)
        shape = (gray.shape[1], gray.shape[0])
        if size is None:
            size = shape
        elif shape != size:
            raise InputError(path, "", f"image is {shape[0]}x{shape[1]} pixels but "
                                       f"{paths[0].name} is {size[0]}x{size[1]}; calibration "
                                       "images must share one size")
        corners.append(detect_corners(gray, board))
        if progress is not None:
            progress(1)
    if all(c is None for c in corners):
        listed = ", ".join(p.name for p in paths[:5]) + (" ..." if len(paths) > 5 else "")
        check = ("the square count (COLSxROWS), the marker size and the dictionary"
                 if board.kind == "charuco" else "the inner-corner count (COLSxROWS)")
        raise InputError(paths[0].parent, "images", f"board {board.kind} {board.cols}x"
                                                    f"{board.rows} not found in any of the "
                                                    f"{len(paths)} images ({listed}); check "
                                                    f"{check}")
    assert size is not None
    return Detections(paths, corners, size[0], size[1])
