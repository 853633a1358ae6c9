"""A simulated light stage that speaks docs/rig-protocol.md over a local socket.

- :mod:`rig.sim.device`: the controller's firmware logic, with fault injection;
- :mod:`rig.sim.server`: that device on ``socket://127.0.0.1:PORT`` for pyserial;
- :mod:`rig.sim.optics`: the frames (a textured Lambertian sphere in numpy, not abs's renderer);
- :mod:`rig.sim.abs_optics`: or frames rendered by abs (a Lambertian box, Mitsuba ray traced);
- :mod:`rig.sim.camera`: the camera on the controller's remote-release pin.

:class:`SimulatedRig` puts them together: the host drives it with the same transport, client,
camera and runner as real hardware, only the port is a socket URL.
"""

from __future__ import annotations

from pathlib import Path

from rig.sim.camera import ShutterCamera
from rig.sim.device import DeviceState, Faults, SimulatedDevice
from rig.sim.optics import Dome, default_dome, render_frame
from rig.sim.server import SimulatedRigServer

__all__ = ["SimulatedRig", "SimulatedDevice", "Faults", "DeviceState", "SimulatedRigServer",
           "ShutterCamera", "Dome", "default_dome", "render_frame"]


class SimulatedRig:
    """A simulated controller, its dome and its camera, served on a local port.

    Parameters
    ----------
    drop_folder : Path
        Where the simulated camera saves images.
    boards, leds_per_board : int
        LED layout.
    width, height : int
        Image size, pixels.
    faults : Faults, optional
        Failures to inject.
    renderer : str
        ``"sphere"`` (numpy, :mod:`rig.sim.optics`, milliseconds a frame) or ``"abs"``
        (:mod:`rig.sim.abs_optics`, about 0.3 s a frame at 32x24).

    Attributes
    ----------
    url : str
        ``socket://127.0.0.1:PORT``: the port to give the host.
    """

    def __init__(self, drop_folder: Path, boards: int = 3, leds_per_board: int = 12,
                 width: int = 32, height: int = 24, faults: Faults | None = None,
                 renderer: str = "sphere"):
        self.dome = default_dome(boards, leds_per_board)
        if renderer == "sphere":
            def render(state: DeviceState, exposure_s: float):
                return render_frame(self.dome, width, height, state.angle_deg, state.global_level,
                                    state.leds, exposure_s)
        elif renderer == "abs":
            from rig.sim.abs_optics import AbsBoxRenderer

            render = AbsBoxRenderer(self.dome, width, height)
        else:
            raise ValueError(f"renderer must be 'sphere' or 'abs', got {renderer!r}")
        self.camera = ShutterCamera(drop_folder, render)
        self.device = SimulatedDevice(boards, leds_per_board, faults, on_shoot=self.camera)
        self.server = SimulatedRigServer(self.device)
        self.url = self.server.url

    def close(self) -> None:
        self.server.stop()

    def __enter__(self) -> SimulatedRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
