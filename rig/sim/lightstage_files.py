"""The simulated rig's geometry and mesh, written into a session folder for ``abs lightstage``.

A real rig's geometry file comes from calibration (issue 27, part 3); the simulated rig knows
its own exactly, so ``abs rig capture --simulate`` writes it beside the frames: ``geometry.json``
(:mod:`abs.lightstage.geometry`) and ``mesh.ply``, an icosphere of the simulated sphere's radius
(the numpy camera renders an exact sphere; subdivision level 3, 1280 triangles of about 8 mm
edges, differs from it by at most 0.3 mm at 5 cm radius).
"""

from __future__ import annotations

from pathlib import Path

from abs.lightstage.dome import dome_geometry
from abs.lightstage.geometry import write_geometry
from rig.sim.optics import SPHERE_RADIUS_M, Dome

__all__ = ["write_lightstage_files"]


def write_lightstage_files(dome: Dome, width: int, height: int, folder: Path) -> None:
    """Write ``geometry.json`` and ``mesh.ply`` of the simulated sphere rig into ``folder``."""
    import trimesh

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    geometry = dome_geometry(dome.led_positions, dome.camera_eye, dome.fov_y_deg, width, height,
                             dome.led_falloff_exponent, dome.led_intensity_w_sr, dome.gain)
    write_geometry(geometry, folder / "geometry.json")
    trimesh.creation.icosphere(subdivisions=3, radius=SPHERE_RADIUS_M).export(folder / "mesh.ply")
