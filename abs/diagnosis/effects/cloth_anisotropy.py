"""``cloth_anisotropy``: a woven cloth reflects part of its light off its threads, more strongly
along one of its two thread directions, where the scene file's diffuse material reflects it
equally in all directions (Lambertian).

The model (``[materials.NAME] anisotropy = [warp, weft]``: the fractions of the reflected light
that leave by the warp's and the weft's lobes, energy-conserving anisotropic microfacet lobes of
threads along the material's ``thread_direction`` and across it) is
:mod:`abs.render.bsdfs.diffuse`. Its derivative at ``[0, 0]`` is not zero (the lobes move light
between directions at first order), so it is scored by the score test.
"""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import Effect, missing, register
from abs.scene.materials.diffuse import Diffuse


@register
class ClothAnisotropy(Effect):
    name = "cloth_anisotropy"
    # The lobes reweight each cosine-weighted sample by its own amount, so the noise of a
    # fixed-seed render depends on the weights: on the suite's sphere case (truth [0.1, 0.3]) the
    # fit at 8 spp followed it to [0.49, 0.50], raising the training error, whereas at 64 spp it
    # converged to [0.09, 0.31], where the 64-spp error is smallest.
    fit_spp_factor = 8
    # At 64 spp Levenberg-Marquardt converged (to [0.09, 0.31] on that case), but the first step
    # of the Gauss-Newton refinement, from two independent noisy Jacobians, jumped by the whole
    # trust radius in every coordinate (the Mitsuba-photographed case: training loss 0.034 ->
    # 0.090), and the averaged result was worse than the control. Without it that case is found.
    fit_refinement = False
    # For the same reason the paired holdout test of shared seeds is blind to it: on that case the
    # holdout RMSE fell 0.0524 -> 0.0517 (z = 1.3) while the noise-free (crossed) error fell
    # 0.0234 -> 0.0187 (z = 9.9).
    crossed_comparison = True

    def targets(self, scene, compiled) -> list[str]:
        used = {o.material for o in scene.objects}
        # Materials on some object whose threads' lobes sit at their null value, or diffuse ones
        # whose file names no thread at all (they compile to Mitsuba's diffuse and have no
        # anisotropy parameter until add() gives them one): a Lambertian surface either way.
        return [name for name in scene.materials
                if name in used and (missing(scene, compiled.specs, f"{name}.anisotropy")
                                     or (isinstance(scene.materials[name], Diffuse)
                                         and not scene.materials[name].threads))]

    def add(self, data: dict, target: str) -> None:
        data["materials"][target]["anisotropy"] = [0.0, 0.0]

    def parameters(self, target: str) -> tuple[str, ...]:
        return (f"{target}.anisotropy",)

    def explain(self, target: str, values: dict) -> str:
        warp, weft = np.asarray(values[f"{target}.anisotropy"], float).ravel()[:2]
        stronger = "along" if warp >= weft else "across"
        return (f"The material '{target}' reflects like a woven cloth: {100 * warp:.2g} % of its "
                f"reflected light ({warp:.2g}) leaves by the lobe of the threads along its "
                f"thread_direction and {100 * weft:.2g} % ({weft:.2g}) by the lobe of those across "
                f"it, so it looks brighter where light glances {stronger} that direction; the "
                f"scene file reflects it equally in all directions (Lambertian).")
