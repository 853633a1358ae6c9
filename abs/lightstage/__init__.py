"""Light-stage reflectance measurement (issue 27, parts 2 and 3): from a capture session to
per-point reflectance models and held-out renders, and the calibration of the lights.

One concept a module:

- :mod:`~abs.lightstage.geometry`: the rig's geometry file (cameras, turntable axis, LEDs, their
  radial attenuation, sensor gain), read and written as JSON;
- :mod:`~abs.lightstage.raycast`: rays against the object's mesh with Mitsuba (first hits and
  shadow rays);
- :mod:`~abs.lightstage.surface`: uniformly spaced surface points by per-triangle subdivision,
  with constant-time lookup from a ray hit;
- :mod:`~abs.lightstage.session`: a rig session folder's LED frames, HDR brackets merged;
- :mod:`~abs.lightstage.measure`: every pixel of every frame onto the mesh, as
  ``(point, normal, light, view, value)`` measurements of ``f_r cos(theta_l)``;
- :mod:`~abs.lightstage.normalise`: the isotropic angles of a measurement;
- :mod:`~abs.lightstage.models`: Lambert, Blinn-Phong and Cook-Torrance (GGX);
- :mod:`~abs.lightstage.fit`: per point and channel robust, bounded fits of the three models;
- :mod:`~abs.lightstage.render`: frames from per-point models (held-out renders), from an
  analytic material or from regions of measured materials (the benchmark's forward model), and
  the MAE of thesis Eq. 4.1;
- :mod:`~abs.lightstage.pcafit`: abs's data-driven ``brdf_pca`` model fitted per surface point;
- :mod:`~abs.lightstage.ledball`: LED positions from a mirror ball's highlights;
- :mod:`~abs.lightstage.greyboard`: the LEDs' radial attenuation and intensities from a grey board;
- :mod:`~abs.lightstage.calibration`: the calibration folder and the refined geometry file;
- :mod:`~abs.lightstage.calsim`: simulated calibration frames of a rig whose truth is known.

docs/lightstage.md describes the pipeline, its conventions and what is not done.
"""
