"""``camera_misalignment``: the photographs' cameras are not the calibrated ones, so the image of
the scene is shifted, scaled or warped against the rendering and the residual lines up along
edges (the checkerboard's, the objects' outlines). Two forms, offered as two candidates:

- target ``sensor``: ``[sensor] intrinsics_offset``, a principal point or focal length off by a
  pixel or so (the camera matrix of the calibration is wrong);
- target ``cameras``: ``[sensor] camera_turn``, every camera turned by the same small rotation
  about its centre (a mount or the extrinsic calibration is off by a fraction of a degree).

Both render as a resampling of the image (``abs.render.sensor``), exact for a pinhole. To first
order a turn by ``a`` moves the image like a principal-point shift of ``f a`` pixels, so the two
forms score alike and both are fitted (:func:`abs.diagnosis.diagnose._clear_winner`); they
differ towards the image's edges, where a turn's shift grows by about ``(x / f)^2`` of itself,
which a focal error partly mimics. Once either form is in the scene file (fitted or set),
neither is offered. Neither models a different error per view or a translation of a camera
(parallax).
"""

from __future__ import annotations

import numpy as np

from abs.diagnosis.effects.base import missing, register
from abs.diagnosis.effects.sensor_field import SensorField


@register
class CameraMisalignment(SensorField):
    name = "camera_misalignment"
    field = "intrinsics_offset"
    #: Target -> ``[sensor]`` field of each form.
    forms = {"sensor": "intrinsics_offset", "cameras": "camera_turn"}

    def targets(self, scene, compiled) -> list[str]:
        absent = {t: missing(scene, compiled.specs, f"sensor.{f}") for t, f in self.forms.items()}
        return list(self.forms) if all(absent.values()) else []

    def add(self, data: dict, target: str) -> None:
        from abs.scene.scene import SensorSpec

        field = self.forms[target]
        data.setdefault("sensor", {})[field] = SensorSpec.null(field).tolist()

    def parameters(self, target: str) -> tuple[str, ...]:
        return (f"sensor.{self.forms[target]}",)

    def explain(self, target: str, values: dict) -> str:
        if target == "cameras":
            turn = np.asarray(values["sensor.camera_turn"], float).ravel()
            return (f"The photographs' cameras are turned against their calibrated poses by "
                    f"{np.degrees(np.linalg.norm(turn)):.2f} degrees (rotation vector "
                    f"{turn[0]:+.4f}/{turn[1]:+.4f}/{turn[2]:+.4f} rad about the cameras' x/y/z), "
                    f"the same for every view, so edges and outlines are misplaced: a mount or "
                    f"the extrinsic calibration is off.")
        dcx, dcy, dfx = np.asarray(values["sensor.intrinsics_offset"], float).ravel()
        return (f"The photographs' camera is not the calibrated one: the image sits "
                f"{dcx:+.2f}/{dcy:+.2f} pixels (x/y, full resolution) from where the calibration "
                f"puts it and its focal length differs by {dfx:+.2f} pixels, so edges and "
                f"outlines are misplaced; a principal-point or focal-length error of the "
                f"calibration.")
