"""The simulated structured-light scanner: two cameras and a projector on a fixed baseline, a
point-light scene light, and a turntable; and the icosphere samples it scans.

Frames (docs/conventions.md): world +y up, metres, OpenCV cameras. The turntable axis is the world
y axis through the origin, where the sample's centre sits. Turntable step ``k`` rotates the sample
by ``angle[k]`` about +y; the study works in the *sample's* frame, in which the sample is fixed and
the rig turns by ``-angle[k]`` (same images, simpler bookkeeping).

The geometry follows the seed paper's description of a DTU-style scanner (two machine-vision
cameras either side of a projector, about 0.6 m from the turntable, a separate scene light): the
exact distances are not published in what we could read, so the numbers below are plausible
stand-ins, recorded in the study's output.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abs.camera.pinhole import intrinsics_from_fov, look_at

__all__ = ["RigCamera", "SampleMesh", "ScannerRig", "default_rig", "icosphere", "rotation_y"]

SAMPLE_DIAMETER_M = 0.1
"""Diameter of the scanned icospheres, metres (100 mm as in the paper)."""


def rotation_y(angle: float) -> np.ndarray:
    """Rotation matrix about +y by ``angle`` radians (right-handed), shape (3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class RigCamera:
    """An OpenCV pinhole camera of the rig (``x_cam = R @ X + t``, pixels, metres)."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, metres."""
        return -self.R.T @ self.t

    def at_step(self, angle: float) -> RigCamera:
        """The camera in the frame of a sample turned by ``angle`` (rad) about +y."""
        return RigCamera(self.K, self.R @ rotation_y(angle), self.t, self.width, self.height)


@dataclass(frozen=True)
class ScannerRig:
    """Cameras, projector and scene light (world frame), and the turntable steps.

    Parameters
    ----------
    cameras : tuple of RigCamera
        The two cameras.
    projector_position : np.ndarray
        (3,) projector centre, metres. The projector only serves geometry acquisition (the mesh
        is given here), so it does not light the BRDF images.
    light_position : np.ndarray
        (3,) position of the point-light scene light, metres.
    light_intensity : float
        Radiant intensity of the scene light per RGB channel, W/sr (any consistent unit: the
        BRDF samples divide it out).
    turntable_angles : np.ndarray
        (S,) rotation of the sample about +y at each step, radians.
    """

    cameras: tuple[RigCamera, ...]
    projector_position: np.ndarray
    light_position: np.ndarray
    light_intensity: float
    turntable_angles: np.ndarray = field(default_factory=lambda: np.linspace(0.0, np.pi, 10, endpoint=False))

    def light_at_step(self, angle: float, light_position: np.ndarray | None = None) -> np.ndarray:
        """Light position in the frame of a sample turned by ``angle`` (rad), metres."""
        p = self.light_position if light_position is None else light_position
        return rotation_y(-angle) @ np.asarray(p, float)

    def describe(self) -> dict:
        """JSON-ready description (metres, radians, pixels)."""
        return {
            "cameras": [{"K": c.K.tolist(), "R": c.R.tolist(), "t": c.t.tolist(), "width": c.width,
                         "height": c.height, "center_m": c.center.tolist()} for c in self.cameras],
            "projector_position_m": np.asarray(self.projector_position).tolist(),
            "light_position_m": np.asarray(self.light_position).tolist(),
            "light_intensity_w_per_sr": float(self.light_intensity),
            "turntable_angles_rad": np.asarray(self.turntable_angles).tolist(),
        }


def default_rig(width: int = 640, height: int = 480, steps: int = 10,
                sweep_rad: float = np.pi) -> ScannerRig:
    """The study's scanner.

    Cameras 0.3 m apart at (±0.15, 0.15, 0.55) m with the projector between them, all aimed at the
    sample centre; the scene light up and to the left at (-0.35, 0.4, 0.3) m (0.61 m from the
    sample); a vertical field of view of 16 degrees, so the 100 mm sphere fills about 60 % of the
    image height; ``steps`` turntable positions over ``sweep_rad`` (10 over 180 degrees).
    """
    eyes = (np.array([-0.15, 0.15, 0.55]), np.array([0.15, 0.15, 0.55]))
    K = intrinsics_from_fov(width, height, np.deg2rad(16.0))
    cameras = []
    for eye in eyes:
        R, t = look_at(eye, np.zeros(3))
        cameras.append(RigCamera(K, R, t, width, height))
    return ScannerRig(
        cameras=tuple(cameras),
        projector_position=np.array([0.0, 0.15, 0.57]),
        light_position=np.array([-0.35, 0.4, 0.3]),
        light_intensity=1.0,
        turntable_angles=np.linspace(0.0, sweep_rad, steps, endpoint=False),
    )


@dataclass(frozen=True)
class SampleMesh:
    """A triangle mesh in the sample's frame (metres) with unit vertex normals."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])


def icosphere(subdivisions: int, diameter_m: float = SAMPLE_DIAMETER_M) -> SampleMesh:
    """trimesh's icosphere centred at the origin, with its exact (radial) vertex normals.

    Subdivisions 1, 3 and 5 give 42, 642 and 10242 vertices.
    """
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.5 * diameter_m)
    vertices = np.asarray(mesh.vertices, np.float64)
    normals = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    return SampleMesh(vertices, np.asarray(mesh.faces, np.int64), normals)
