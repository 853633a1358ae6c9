"""How much rendering a run used, counted where renders happen.

Fits, scans, samplers and diagnoses report their cost in renders and in samples (pixels times
samples per pixel), the unit that compares runs at different resolutions and sample counts. Every
problem built over one :class:`~abs.model.build.ForwardModel` shares its counter, so a fit that
switches resolution (Adam's schedules) or renders its before/after images still counts once.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RenderCounter"]


@dataclass
class RenderCounter:
    """Renders and samples used so far.

    Attributes
    ----------
    renders : int
        Primal, forward-mode and reverse-mode renders of one view (each counts once; a Jacobian
        pass of an IOR counts the renders its central difference makes, two or three, see
        ``CompiledScene.forward_renders``).
    samples : int
        Camera samples traced: ``width * height * spp`` (and a sample boost's extra ones) summed
        over the renders.
    """

    renders: int = 0
    samples: int = 0

    def add(self, camera, spp: int) -> None:
        """Count one render of ``camera`` (pixels) at ``spp`` samples per pixel."""
        self.renders += 1
        self.samples += camera.samples(spp)
