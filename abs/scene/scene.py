"""The scene representation: what a scene file says, as immutable Python objects.

A :class:`Scene` is pure data (no Mitsuba objects); :func:`abs.render.compile_scene` turns it into
a differentiable Mitsuba scene. See ``docs/scene-format.md`` for the file format.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from abs.scene.materials.base import Material

#: A chromium mirror ball's complex index per R, G, B (real and imaginary parts): Johnson and
#: Christy's chromium (refractiveindex.info, ``../shared/data/refractiveindex_info``) through
#: :func:`abs.colour.optical_constants_rgb`, to two decimals. The default probe ball.
CHROMIUM_IOR_RGB = (3.28, 3.05, 2.37)
CHROMIUM_K_RGB = (3.31, 3.31, 3.14)

__all__ = ["RenderSettings", "EnvironmentSpec", "SensorSpec", "ObjectSpec", "Prior", "Scene"]


@dataclass(frozen=True)
class RenderSettings:
    """``[render]``: samples per pixel and maximum path length (segments)."""

    spp: int = 64
    max_depth: int = 12


@dataclass(frozen=True)
class EnvironmentSpec:
    """``[environment]``: a lat-long HDR map, at infinity unless ``inverse_distance`` > 0.

    ``rotation`` (radians, about world +y) is applied after ``to_world``, and ``orientation``
    after both: a correction of the map's orientation about all three axes, a rotation vector
    (axis times angle, radians, world frame; zeros: none). With ``inverse_distance`` = 1/R > 0
    (1/m) the map lies on a sphere of radius R metres around ``center`` (world, metres), and
    light from it shows parallax. ``probe_fresnel`` ``c`` (per R, G, B, dimensionless; zeros:
    none) is the fraction of the mirror ball's angle-dependent reflectance left in a light-probe
    map: the light from map direction ``l`` is the map's divided by ``1 + c (F(cos_i) / F(1) - 1)``,
    ``F`` the exact Fresnel reflectance of the ball's metal (complex index ``probe_ior + i
    probe_k`` per R, G, B; default chromium's), ``cos_i = sqrt((1 + l.v)/2)`` the ball's angle of
    incidence for ``l`` seen from ``probe_view`` ``v`` (a unit vector in the map's own frame, from
    the ball towards the camera that photographed it).
    """

    file: Path
    scale: float = 1.0
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    rotation: float = 0.0
    inverse_distance: float = 0.0
    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    probe_fresnel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    probe_view: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    probe_ior: np.ndarray = field(default_factory=lambda: np.array(CHROMIUM_IOR_RGB))
    probe_k: np.ndarray = field(default_factory=lambda: np.array(CHROMIUM_K_RGB))


@dataclass(frozen=True)
class SensorSpec:
    """``[sensor]``: what the camera does to the radiance after the lens (docs/scene-format.md).

    Each field's default is its null value, which leaves the rendering unchanged.

    Attributes
    ----------
    vignetting : ndarray, shape (2,)
        ``[k1, k2]``: the image is multiplied by ``1 + k1 r^2 + k2 r^4``, ``r`` the distance from
        the principal point in units of the focal length (dimensionless).
    response : ndarray, shape (3,)
        Per-channel exponent ``gamma`` of the sensor response ``out = in ** gamma`` (1 = linear).
    stray_light : ndarray, shape (3,)
        Veiling glare / ambient offset added to every pixel, per R, G, B, in radiance units.
    colour_matrix : ndarray, shape (9,)
        The 3x3 matrix ``M``, row-major, that takes the rendering's linear RGB to the
        photographs' (``out_i = sum_j M_ij in_j``, dimensionless); the identity is no colour
        transform. Applied after vignetting and stray light, before the response.
    intrinsics_offset : ndarray, shape (3,)
        ``[dcx, dcy, dfx]``, pixels of the full-resolution photographs: the photographs' camera
        matrix minus the calibrated one (``cameras.json``): principal point moved by
        ``(dcx, dcy)``, focal length ``fx`` by ``dfx`` with ``fy`` and the skew scaled alike;
        zeros: the calibration is right. Rendered as a resampling of the image (exact for a
        pinhole; ``abs.render.sensor``), applied first.
    camera_turn : ndarray, shape (3,)
        Rotation vector (radians, camera frame: x right, y down, z forward) by which every
        photograph's camera is turned about its own centre against the calibrated pose: a point
        at ``x`` in the calibrated camera's frame is at ``R(camera_turn) x`` in the
        photographs'. Zeros: the calibrated poses are right. Rendered, with
        ``intrinsics_offset``, as the resampling by the homography ``K R^T K'^-1`` (exact for a
        pinhole turned about its centre).
    """

    # field: (size, unit, lower, upper, null value: one number for every entry, or ``size``
    # numbers); the loader and the parameter catalogue read it.
    FIELDS = {
        "vignetting": (2, "1", -2.0, 2.0, 0.0),
        "response": (3, "1", 0.2, 5.0, 1.0),
        "stray_light": (3, "radiance", 0.0, float("inf"), 0.0),
        # A real camera's colour matrix can have negative entries (cross-talk correction), so
        # no entry is bounded.
        "colour_matrix": (9, "1", -float("inf"), float("inf"), tuple(np.eye(3).ravel())),
        # Bounded to offsets a calibration could plausibly miss by; beyond them the resampling's
        # clamped border would dominate.
        "intrinsics_offset": (3, "px", -50.0, 50.0, 0.0),
        # A few degrees: beyond them the resampling's clamped border would dominate.
        "camera_turn": (3, "rad", -0.1, 0.1, 0.0),
    }

    vignetting: np.ndarray = field(default_factory=lambda: np.zeros(2))
    response: np.ndarray = field(default_factory=lambda: np.ones(3))
    stray_light: np.ndarray = field(default_factory=lambda: np.zeros(3))
    colour_matrix: np.ndarray = field(default_factory=lambda: np.eye(3).ravel())
    intrinsics_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    camera_turn: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @staticmethod
    def null(name: str) -> np.ndarray:
        """The null value of field ``name``, one entry per scalar."""
        size, _, _, _, null = SensorSpec.FIELDS[name]
        return np.broadcast_to(np.asarray(null, np.float64), (size,)).copy()


@dataclass(frozen=True)
class ObjectSpec:
    """``[[objects]]``: a mesh with a material; ``pose`` (``[tx, ty, tz, rx, ry, rz]``) and
    ``placement`` (``[tx, tz, ry]`` on the ground plane) are corrections on top of ``to_world``
    (see docs/conventions.md)."""

    name: str
    mesh: Path
    material: str
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    pose: np.ndarray = field(default_factory=lambda: np.zeros(6))
    placement: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class Prior:
    """``[fit.priors."NAME"]``: an independent Gaussian prior on each scalar of a parameter.

    Attributes
    ----------
    mean : ndarray
        Prior mean, one entry per scalar of the parameter, in the parameter's unit.
    sd : ndarray
        Standard deviation (> 0), same shape and unit as ``mean``.
    """

    mean: np.ndarray
    sd: np.ndarray

    def __post_init__(self):
        # Read-only float copies: the dataclass is frozen, its arrays should be too.
        for name in ("mean", "sd"):
            arr = np.array(getattr(self, name), dtype=np.float64, ndmin=1)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.mean.shape != self.sd.shape or self.mean.ndim != 1:
            raise ValueError(f"prior mean and sd must be vectors of one size, got shapes "
                             f"{list(self.mean.shape)} and {list(self.sd.shape)}")
        if not (np.all(np.isfinite(self.mean)) and np.all(np.isfinite(self.sd)) and np.all(self.sd > 0)):
            raise ValueError(f"prior needs finite mean and sd > 0, got mean {self.mean.tolist()}, "
                             f"sd {self.sd.tolist()}")


@dataclass(frozen=True)
class Scene:
    """A whole scene file.

    Attributes
    ----------
    source : Path
        The file it was read from (assets are resolved relative to it).
    fit_parameters : tuple of str
        Names from ``[fit] parameters`` (fitted by default).
    fit_priors : dict of str to Prior
        ``[fit.priors]``: Gaussian priors by parameter name (any known parameter, fitted or not).
    """

    source: Path
    render: RenderSettings
    environment: EnvironmentSpec
    materials: dict[str, Material]
    objects: tuple[ObjectSpec, ...]
    sensor: SensorSpec = field(default_factory=SensorSpec)
    fit_parameters: tuple[str, ...] = ()
    fit_priors: dict[str, Prior] = field(default_factory=dict)

    def object(self, name: str) -> ObjectSpec:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise KeyError(name)

    def with_render(self, **changes) -> "Scene":
        """A copy with some ``[render]`` settings changed (e.g. ``spp=4`` for tests)."""
        return replace(self, render=replace(self.render, **changes))
