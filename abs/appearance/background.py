"""Lighting estimated from an image's background, after the paper's recipe (issue 29).

The objects are removed and their holes filled from the mirrored background
(:func:`abs.editing.holes.fill_background`), the largest centred circle of the image is read as
the hemisphere behind the image plane and the front hemisphere as its mirror image
(:func:`abs.editing.environment.environment_from_photograph`, Khan et al. 2006, which the paper
follows). The map is written in abs's lat-long convention for a camera looking along +z with +y
up; :func:`background_to_world` gives the ``environment.to_world`` that puts it around the camera
that took the image.

A coarse estimate by construction: it sees only what lies behind the objects (here the box's
walls), and mirrors that to the front.
"""

from __future__ import annotations

import cv2
import numpy as np

from abs.appearance.geometry import Geometry
from abs.editing.environment import environment_from_photograph
from abs.editing.holes import fill_background

__all__ = ["environment_from_background", "background_to_world"]


def environment_from_background(image: np.ndarray, geometry: Geometry, width: int = 256) -> np.ndarray:
    """A lat-long map ``(width // 2, width, 3)`` from ``image`` with its objects removed.

    Parameters
    ----------
    image : np.ndarray
        ``(height, width, 3)`` linear RGB.
    geometry : Geometry
        Its material ids; the objects and a 2-pixel rim (their silhouettes mix object and
        background) are filled before the map is made.
    width : int
        Width of the map, pixels.
    """
    objects = cv2.dilate((geometry.ids > 0).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    return environment_from_photograph(fill_background(np.asarray(image, np.float32), objects), width)


def background_to_world(R: np.ndarray) -> np.ndarray:
    """``environment.to_world`` (4x4) of a map from :func:`environment_from_background` for a
    camera with world-to-camera rotation ``R``: the map's frame is ``(-x, -y, z)`` of the
    camera's (docs/conventions.md), and the camera's frame is ``R^T`` of the world's."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(R, float).T @ np.diag([-1.0, -1.0, 1.0])
    return m
