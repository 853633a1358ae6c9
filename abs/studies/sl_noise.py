"""Scanner errors of the variational study: what the scanner *believes* about the scan, and a
registry of the error types that perturb it (adding an error type is adding a function).

The images are always rendered with the true geometry and light; an error changes only the
scanner's estimate used to turn pixels into BRDF samples, as a calibration or reconstruction error
of a real scanner would. Each error type is studied alone, as in the paper's Table 2: vertex noise
moves positions but keeps the normals, normal noise tilts normals but keeps positions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from abs.studies.sl_rig import SampleMesh

__all__ = ["NOISE_TYPES", "NoiseType", "ScanEstimate", "perturb", "register_noise"]


@dataclass(frozen=True)
class ScanEstimate:
    """The scanner's belief: sample mesh (sample frame), light position (world, metres) and light
    intensity (W/sr)."""

    mesh: SampleMesh
    light_position: np.ndarray
    light_intensity: float


@dataclass(frozen=True)
class NoiseType:
    """One error type: its name, the unit of its σ, the paper's levels, and the perturbation."""

    name: str
    unit: str
    levels: tuple[float, ...]
    apply: Callable[[ScanEstimate, float, np.random.Generator], ScanEstimate]
    description: str


NOISE_TYPES: dict[str, NoiseType] = {}


def register_noise(name: str, unit: str, levels: tuple[float, ...], description: str):
    """Decorator registering ``apply(estimate, sigma, rng) -> estimate`` as an error type."""
    def wrap(apply):
        NOISE_TYPES[name] = NoiseType(name, unit, levels, apply, description)
        return apply
    return wrap


def perturb(estimate: ScanEstimate, noise: str, sigma: float, rng: np.random.Generator) -> ScanEstimate:
    """One random realisation of error type ``noise`` at level ``sigma`` (in the type's unit)."""
    return NOISE_TYPES[noise].apply(estimate, float(sigma), rng)


@register_noise("vertex_position", "mm", (1.0, 3.0, 5.0),
                "every vertex moved by an isotropic Gaussian offset, σ per axis")
def _vertex_position(estimate: ScanEstimate, sigma_mm: float, rng: np.random.Generator) -> ScanEstimate:
    mesh = estimate.mesh
    moved = mesh.vertices + rng.normal(0.0, sigma_mm * 1e-3, mesh.vertices.shape)
    return replace(estimate, mesh=SampleMesh(moved, mesh.faces, mesh.normals))


@register_noise("normal_tilt", "deg", (5.0, 10.0, 30.0),
                "every normal tilted by |N(0, σ)| towards a uniformly random azimuth")
def _normal_tilt(estimate: ScanEstimate, sigma_deg: float, rng: np.random.Generator) -> ScanEstimate:
    mesh = estimate.mesh
    n = mesh.normals
    tangent, bitangent = tangent_frame(n)
    tilt = np.abs(rng.normal(0.0, np.deg2rad(sigma_deg), len(n)))[:, None]
    azimuth = rng.uniform(0.0, 2.0 * np.pi, len(n))[:, None]
    direction = np.cos(azimuth) * tangent + np.sin(azimuth) * bitangent
    tilted = np.cos(tilt) * n + np.sin(tilt) * direction
    return replace(estimate, mesh=SampleMesh(mesh.vertices, mesh.faces, tilted))


@register_noise("light_position", "mm", (10.0, 25.0, 50.0),
                "the calibrated light position off by one isotropic Gaussian offset per scan, σ per axis")
def _light_position(estimate: ScanEstimate, sigma_mm: float, rng: np.random.Generator) -> ScanEstimate:
    offset = rng.normal(0.0, sigma_mm * 1e-3, 3)
    return replace(estimate, light_position=np.asarray(estimate.light_position, float) + offset)


@register_noise("light_intensity", "%", (5.0, 10.0, 20.0),
                "the calibrated intensity off by a relative Gaussian error per scan")
def _light_intensity(estimate: ScanEstimate, sigma_pct: float, rng: np.random.Generator) -> ScanEstimate:
    factor = 1.0 + rng.normal(0.0, sigma_pct / 100.0)
    # A calibration cannot return a non-positive intensity; 20 % never gets close in practice.
    return replace(estimate, light_intensity=estimate.light_intensity * max(factor, 1e-3))


def tangent_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal tangents (t, b) with (t, b, n) right-handed, for unit normals ``n`` (N, 3).

    Duff et al.'s branchless form of Frisvad's construction (stable at n = -z).
    """
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    bt = np.stack([b, sign + y * y * a, -y], axis=1)
    return t, bt
