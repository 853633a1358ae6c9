"""A simulated light stage that speaks docs/rig-protocol.md over a local socket.

- :mod:`rig.sim.device`: the controller's firmware logic, with fault injection;
- :mod:`rig.sim.server`: that device on ``socket://127.0.0.1:PORT`` for pyserial;
- :mod:`rig.sim.pty_server`: or on a pseudo-terminal (``/dev/pts/N``, POSIX);
- :mod:`rig.sim.optics`: the frames (a textured Lambertian sphere in numpy, not abs's renderer);
- :mod:`rig.sim.abs_optics`: or frames rendered by abs (a Lambertian box, Mitsuba ray traced);
- :mod:`rig.sim.camera`: the camera on the controller's remote-release pin.

:class:`SimulatedRig` puts them together: the host drives it with the same transport, client,
camera and runner as real hardware, only the port is a socket URL.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from rig.sim.camera import ShutterCamera
from rig.sim.device import DeviceState, Faults, SimulatedDevice
from rig.sim.optics import Dome, default_dome, render_frame
from rig.sim.server import SimulatedRigServer

if TYPE_CHECKING:
    from rig.sim.pty_server import SimulatedPtyServer

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
    link : str
        ``"socket"`` (``socket://127.0.0.1:PORT``) or ``"pty"`` (a pseudo-terminal path).

    Attributes
    ----------
    url : str
        ``socket://127.0.0.1:PORT``: the port to give the host.
    """

    def __init__(self, drop_folder: Path, boards: int = 3, leds_per_board: int = 12,
                 width: int = 32, height: int = 24, faults: Faults | None = None,
                 renderer: str = "sphere", link: str = "socket"):
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
        if link == "socket":
            self.server: SimulatedRigServer | SimulatedPtyServer = SimulatedRigServer(self.device)
        elif link == "pty":
            from rig.sim.pty_server import SimulatedPtyServer

            self.server = SimulatedPtyServer(self.device)
        else:
            raise ValueError(f"link must be 'socket' or 'pty', got {link!r}")
        self.url = self.server.url

    def close(self) -> None:
        self.server.stop()

    def __enter__(self) -> SimulatedRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
