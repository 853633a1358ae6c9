"""Image-based material editing by analysis by synthesis (issue 30, "Beyond the paper").

Importing this package registers the ``synthesis`` method of :func:`abs.editing.edit`: the
baseline's estimates start a fit of the photograph with abs's renderer (an inflated mesh from
the mask, the environment with the photograph's background as its backdrop, the current
material and the environment's scale), and the edit is a rendering of the target material in
the fitted scene. One concept per module:

- :mod:`~abs.resynthesis.inflation`: a closed mesh from the mask;
- :mod:`~abs.resynthesis.backdrop`: the environment map with the photograph's background;
- :mod:`~abs.resynthesis.materials`: the current material and the targets as scene materials;
- :mod:`~abs.resynthesis.highlight`: a sun fitted to the highlight, and the roughness it shows;
- :mod:`~abs.resynthesis.studio`: the scene file, mesh, map and capture on disk;
- :mod:`~abs.resynthesis.method`: fit, render, composite.

docs/editing.md, "Analysis by synthesis".
"""

from abs.editing.edit import edit, register_method
from abs.resynthesis.method import (FittedScene, SynthesisSettings, composite, edit_fitted,
                                    fit_photograph, render_material, synthesis_edit)

register_method("synthesis", synthesis_edit)

__all__ = ["edit", "SynthesisSettings", "FittedScene", "fit_photograph", "render_material",
           "edit_fitted", "synthesis_edit", "composite"]
