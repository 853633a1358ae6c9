"""Simulated frames rendered by abs: a Lambertian box lit by one point light, Mitsuba ray traced.

The alternative to :mod:`rig.sim.optics` (``abs rig capture --simulate --sim-renderer abs``). It
renders with ``abs.studies.sl_capture.render_point_lit``, abs's direct-lighting pass on Mitsuba
(camera rays, shadow rays, the ``abs_tabulated`` BSDF with a constant, i.e. Lambertian, MERL-layout
table). The object is a flat-shaded box, 8 x 5 x 3 cm, so that turning the table changes the
image (a uniformly coloured sphere would look the same at every angle); the turntable angle is
its pose about +y.

What it does not model, stated here because the manifest names this module:

- An LED's radial attenuation is applied once per LED, at the object's centre, because
  ``render_point_lit`` takes one scalar intensity per light; every LED of the simulated dome aims
  at the centre, so the factor is 1. Per-point attenuation needs a renderer change.
- The global light is a point light at the camera (a ring flash), not a diffuse dome light: the
  renderer has no other light for a bare mesh.
- Each frame costs about 0.3 s at 32x24 and 4 samples per pixel on two CPU cores (a kernel per
  light position), against milliseconds for the numpy sphere; the tests use the sphere.
"""

from __future__ import annotations

import numpy as np

from rig.sim.device import DeviceState
from rig.sim.optics import Dome

__all__ = ["AbsBoxRenderer"]

BOX_EXTENTS_M = (0.08, 0.05, 0.03)
"""Size of the rendered box along x, y, z, metres."""

ALBEDO = 0.6
"""The box's diffuse albedo (grey)."""


def _flat_box():
    """The box as a SampleMesh with one vertex per face corner and the face's normal, so the
    renderer shades it flat (shared corner vertices would average the normals into a blob)."""
    import trimesh

    from abs.studies.sl_rig import SampleMesh

    box = trimesh.creation.box(extents=BOX_EXTENTS_M)
    faces = np.asarray(box.faces)
    vertices = np.asarray(box.vertices)[faces].reshape(-1, 3)
    normals = np.repeat(np.asarray(box.face_normals), 3, axis=0)
    return SampleMesh(vertices, np.arange(len(vertices)).reshape(-1, 3), normals)


class AbsBoxRenderer:
    """``render(state, exposure_s) -> image`` for :class:`~rig.sim.camera.ShutterCamera`.

    Parameters
    ----------
    dome : Dome
        LED positions and powers, camera position and gain (as for the numpy sphere).
    width, height : int
        Image size, pixels.
    spp : int
        Samples per pixel.
    """

    def __init__(self, dome: Dome, width: int, height: int, spp: int = 4):
        from abs.camera.pinhole import intrinsics_from_fov, look_at
        from abs.render.variant import set_variant
        from abs.studies.sl_capture import sample_scene
        from abs.studies.sl_rig import RigCamera

        set_variant()
        self.dome = dome
        self.spp = spp
        R, t = look_at(dome.camera_eye, np.zeros(3))
        self.camera = RigCamera(intrinsics_from_fov(width, height, np.deg2rad(dome.fov_y_deg)),
                                R, t, width, height)
        table = np.full((3, 90, 90, 180), ALBEDO / np.pi, np.float32)  # Lambertian: rho / pi
        self.scene = sample_scene(_flat_box(), table)
        self._seed = 0

    def __call__(self, state: DeviceState, exposure_s: float) -> np.ndarray:
        from abs.studies.sl_capture import render_point_lit

        angle = np.deg2rad(state.angle_deg)
        cam = self.camera.at_step(angle)
        # The sample's frame: the object is fixed and the rig turns by -angle (abs.studies.sl_rig).
        c, s = np.cos(-angle), np.sin(-angle)
        to_sample = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        # The ring flash's intensity gives the object's centre the dome's global irradiance.
        eye = np.asarray(self.dome.camera_eye, float)
        flash = self.dome.global_irradiance * float(eye @ eye) * state.global_level / 255.0
        lights = [(eye, flash)]
        lights += [(self.dome.led_positions[b, i], self.dome.led_intensity_w_sr * level / 255.0)
                   for (b, i), level in state.leds.items() if level > 0]
        radiance = np.zeros((cam.height, cam.width, 3), np.float32)
        for position, intensity in lights:
            if intensity <= 0.0:
                continue
            self._seed += 1
            radiance += render_point_lit(self.scene, cam, to_sample @ np.asarray(position, float),
                                         intensity, self.spp, seed=self._seed)
        return np.clip(radiance * exposure_s * self.dome.gain, 0.0, 1.0).astype(np.float32)
