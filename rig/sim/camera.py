"""The simulated camera on the controller's remote-release pin: ``SHOOT`` writes an image file.

It renders with the device's state at the moment the shutter fires (:mod:`rig.sim.optics`, or
:mod:`rig.sim.abs_optics`), so a
frame taken after a restart switched the lights off is dark, exactly the failure the capture
runner must catch. Files are written under a hidden name and renamed, as tethering programs do,
so the host never reads half a file.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from abs.io.images import write_exr
from rig.sim.device import DeviceState

__all__ = ["ShutterCamera", "Renderer"]

Renderer = Callable[[DeviceState, float], np.ndarray]
"""``render(state, exposure_s)``: the (height, width, 3) image in [0, 1] for the device's state."""


class ShutterCamera:
    """``on_shoot`` callback of :class:`~rig.sim.device.SimulatedDevice`.

    Parameters
    ----------
    folder : Path
        The drop folder images appear in.
    render : Renderer
        Makes the image (:func:`rig.sim.optics.render_frame` through
        :class:`rig.sim.SimulatedRig`, or :class:`rig.sim.abs_optics.AbsBoxRenderer`).
    """

    def __init__(self, folder: Path, render: Renderer):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.render = render
        self._count = itertools.count()
        self.written: list[Path] = []

    def __call__(self, exposure_ms: int, state: DeviceState) -> None:
        image = self.render(state, exposure_ms / 1000.0)
        # Unique across processes and restarts: a resumed session must never see a new image
        # under the name of a leftover one.
        name = f"IMG_{time.time_ns()}_{os.getpid()}_{next(self._count):05d}.exr"
        partial = self.folder / ("." + name)  # hidden names are never picked up
        write_exr(partial, image)
        os.replace(partial, self.folder / name)
        self.written.append(self.folder / name)
