"""Simulation studies built on abs's renderer and BRDF basis (one sub-package concept per module).

- :mod:`abs.studies.sl_rig`: the structured-light scanner (cameras, projector, scene light,
  turntable) and the sample icospheres.
- :mod:`abs.studies.sl_capture`: HDR images of a sample rendered with its true BRDF.
- :mod:`abs.studies.sl_sampling`: BRDF samples from the images, with scanner errors.
- :mod:`abs.studies.sl_scoring`: CIEDE2000 between tone-mapped renderings under an environment map.
- :mod:`abs.studies.sl_scanner`: the variational study (Tables 1 and 2), run in parallel.
- :mod:`abs.studies.sl_paper`: the paper's published Tables 1 and 2, read into the study's layout.
- :mod:`abs.studies.sl_compare`: the published tables beside abs's, cell by cell.
"""
