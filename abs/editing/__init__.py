"""Image-based material editing: give an object in one HDR photograph a new material.

The baseline is Khan, Reinhard, Fleming and Bülthoff (2006), "Image-Based Material Editing"
(ACM SIGGRAPH), built as functions over numpy arrays, one concept per module:

- :mod:`~abs.editing.depth`: depth from luminance (sigmoid, bilateral filter, inverse sigmoid);
- :mod:`~abs.editing.gradients`: forward differences, the boosting spline, normals;
- :mod:`~abs.editing.holes`: the background behind the object by mirrored copies;
- :mod:`~abs.editing.environment`: a lat-long environment map from the photograph;
- :mod:`~abs.editing.highlights`: highlight threshold and layer;
- :mod:`~abs.editing.gloss`: more or less gloss (highlight remapping);
- :mod:`~abs.editing.brdf_replace`: a measured BRDF lit by the environment;
- :mod:`~abs.editing.warp`, :mod:`~abs.editing.texture`, :mod:`~abs.editing.transparency`:
  re-texturing, glass and translucency through the gradient warp;
- :mod:`~abs.editing.checks`, :mod:`~abs.editing.spec`, :mod:`~abs.editing.edit`: input checks,
  the target-material grammar and the end-to-end :func:`edit`.

docs/editing.md describes the method, its conventions and what is the paper's and what is ours.
"""

from abs.editing.edit import METHODS, EditResult, EditSettings, edit
from abs.editing.spec import MaterialSpec, parse_material

__all__ = ["edit", "EditSettings", "EditResult", "METHODS", "MaterialSpec", "parse_material"]
