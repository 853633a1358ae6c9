"""CT volume to meshes: the marker spheres and the cleaned glass mesh (the ``mesh`` step).

1. Thresholds (:func:`~abs.reassembly.surfaces.auto_thresholds` unless given).
2. Marker iso-surface at the marker threshold; spheres fitted to its vertices by sequential
   RANSAC (:func:`~abs.reassembly.spheres.ransac_spheres`).
3. Glass iso-surface at the glass threshold (markers included: they are denser).
4. Carve the markers out (faces within ``(1 + epsilon) r_i``), keep the largest piece, close
   every boundary loop.
5. Decimate to ``keep`` of the faces (not below ``min_faces``), then ``rounds`` times √3
   subdivision and decimation to a third.

Everything is in the volume frame, millimetres (see :mod:`.volume`). :func:`write_meshing`
writes the glass mesh in metres (the object's frame for a scene file: the volume frame scaled
to metres) and the markers, in mm, to ``markers.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from abs.errors import InputError, read_json
from abs.reassembly.cleaning import (carve_spheres, decimate, fill_holes, largest_component,
                                     subdivide_decimate)
from abs.reassembly.spheres import SphereFit, ransac_spheres
from abs.reassembly.surfaces import Thresholds, auto_thresholds, iso_surface
from abs.reassembly.volume import Volume

__all__ = ["MeshingSettings", "MeshingResult", "mesh_volume", "write_meshing", "read_markers"]


@dataclass(frozen=True)
class MeshingSettings:
    """Settings of :func:`mesh_volume` (lengths in mm).

    ``glass_threshold`` / ``marker_threshold``: grey values, found from the histogram when
    ``None``. ``marker_radius_mm``: accepted marker radii, ``(max(0.5, 1.5 voxels), 5)`` when
    ``None``. ``epsilon``: carving margin, in ``[0.5, 0.75]`` as the seed. ``keep``: fraction of
    faces kept by the first decimation (the seed: 1 %), not below ``min_faces``. ``rounds``:
    subdivision-decimation rounds (0 skips them).
    """

    glass_threshold: float | None = None
    marker_threshold: float | None = None
    marker_radius_mm: tuple[float, float] | None = None
    epsilon: float = 0.5
    keep: float = 0.01
    min_faces: int = 2000
    rounds: int = 4
    ransac_trials: int = 300
    seed: int = 0


@dataclass
class MeshingResult:
    """The meshes and markers of one volume (volume frame, mm).

    ``glass``: the cleaned glass mesh; ``glass_raw``: its iso-surface before cleaning;
    ``marker_mesh``: the marker iso-surface; ``markers``: the fitted spheres; ``seconds``: wall
    time per stage.
    """

    glass: trimesh.Trimesh
    glass_raw: trimesh.Trimesh
    marker_mesh: trimesh.Trimesh
    markers: list[SphereFit]
    thresholds: Thresholds
    voxel_size_mm: np.ndarray
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def centres_mm(self) -> np.ndarray:
        return np.array([m.centre for m in self.markers]).reshape(-1, 3)

    @property
    def radii_mm(self) -> np.ndarray:
        return np.array([m.radius for m in self.markers])


def mesh_volume(volume: Volume, settings: MeshingSettings = MeshingSettings()) -> MeshingResult:
    """Run the meshing step (see the module docstring).

    Raises
    ------
    InputError
        A volume without markers (no dense material, or no sphere among the dense voxels), or
        ``epsilon`` outside ``[0, 2]``.
    """
    if not 0 <= settings.epsilon <= 2:
        raise InputError(None, "epsilon", f"expected a carving margin in [0, 2] (the seed: 0.5 to "
                                          f"0.75), got {settings.epsilon}")
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    th = None
    if settings.glass_threshold is None or settings.marker_threshold is None:
        # A marker threshold given by hand overrides the check that the volume has markers.
        th = auto_thresholds(volume, min_marker_contrast=1.5 if settings.marker_threshold is None else 0.0)
    thresholds = Thresholds(
        glass=settings.glass_threshold if settings.glass_threshold is not None else th.glass,
        marker=settings.marker_threshold if settings.marker_threshold is not None else th.marker,
        air_level=th.air_level if th else float("nan"), glass_level=th.glass_level if th else float("nan"),
        marker_level=th.marker_level if th else float("nan"))
    if thresholds.marker <= thresholds.glass:
        raise InputError(None, "marker_threshold", f"{thresholds.marker:g} must lie above the glass "
                                                   f"threshold {thresholds.glass:g}")
    seconds["thresholds"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    voxel = float(np.min(volume.voxel_size_mm))
    r_min, r_max = settings.marker_radius_mm or (max(0.5, 1.5 * voxel), 5.0)
    try:
        marker_mesh = iso_surface(volume, thresholds.marker)
    except InputError:
        raise InputError(volume.source, "", f"no markers: no voxel above the marker threshold "
                                            f"{thresholds.marker:g}") from None
    min_inliers = int(max(20, 0.5 * 4 * np.pi * r_min ** 2 / voxel ** 2))
    markers = ransac_spheres(marker_mesh.vertices, tol=0.5 * voxel, r_min=r_min, r_max=r_max,
                             min_inliers=min_inliers, trials=settings.ransac_trials,
                             density=1 / voxel ** 2, min_coverage=0.6, seed=settings.seed)
    if not markers:
        raise InputError(volume.source, "", (
            f"no markers: no sphere of radius {r_min:g} to {r_max:g} mm among the "
            f"{len(marker_mesh.vertices)} vertices above the marker threshold {thresholds.marker:g}"))
    seconds["markers"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    glass_raw = iso_surface(volume, thresholds.glass)
    seconds["glass_iso_surface"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    centres = np.array([m.centre for m in markers])
    radii = np.array([m.radius for m in markers])
    glass = fill_holes(largest_component(carve_spheres(glass_raw, centres, radii, settings.epsilon)))
    seconds["carve_fill"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    target = max(settings.min_faces, int(round(settings.keep * len(glass.faces))))
    glass = decimate(glass, faces=target)
    seconds["decimate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if settings.rounds:
        glass = subdivide_decimate(glass, settings.rounds)
    seconds["subdivide_decimate"] = time.perf_counter() - t0
    return MeshingResult(glass, glass_raw, marker_mesh, markers, thresholds,
                         np.asarray(volume.voxel_size_mm), seconds)


def write_meshing(result: MeshingResult, folder: str | Path) -> Path:
    """Write ``glass.ply`` (metres, object frame = volume frame), ``glass_raw_mm.ply``,
    ``markers_mm.ply`` (iso-surfaces, mm) and ``markers.json``; returns the JSON path."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    glass_m = result.glass.copy()
    glass_m.vertices = glass_m.vertices * 1e-3
    glass_m.export(out / "glass.ply")
    result.glass_raw.export(out / "glass_raw_mm.ply")
    result.marker_mesh.export(out / "markers_mm.ply")
    th = result.thresholds
    data = {
        "frame": "volume: (x, y, z) = (column, row, slice) * voxel size, origin at voxel [0, 0, 0]",
        "units": "mm (glass.ply: m)",
        "voxel_size_mm": np.asarray(result.voxel_size_mm).tolist(),
        "glass_mesh": "glass.ply",
        "glass_mesh_unit": "m",
        "thresholds": {k: (None if not np.isfinite(v) else float(v)) for k, v in vars(th).items()},
        "markers": [{"centre_mm": m.centre.tolist(), "radius_mm": m.radius, "inliers": m.inliers,
                     "rms_mm": m.rms} for m in result.markers],
        "seconds": result.seconds,
        "glass_faces": int(len(result.glass.faces)),
        "glass_watertight": bool(result.glass.is_watertight),
    }
    path = out / "markers.json"
    path.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    return path


def read_markers(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``(centres_mm (n, 3), radii_mm (n,))`` from a ``markers.json`` written by
    :func:`write_meshing` (a folder is taken to hold one)."""
    p = Path(path)
    if p.is_dir():
        p = p / "markers.json"
    data = read_json(p, what="marker file", hint="written by `abs reassemble mesh`")
    try:
        markers = data["markers"]
        centres = np.array([m["centre_mm"] for m in markers], dtype=np.float64).reshape(-1, 3)
        radii = np.array([m.get("radius_mm", np.nan) for m in markers], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(p, "markers", f"expected a list of {{centre_mm: [x, y, z], radius_mm}}: {exc}") from None
    return centres, radii
