"""The simulated controller on a pseudo-terminal: a real tty path such as ``/dev/pts/7``.

A pty goes through the same termios layer as a USB serial port (line discipline, raw mode, baud
settings that pyserial applies), which a socket URL skips. POSIX only.
"""

from __future__ import annotations

import os
import select
import threading
import tty

from rig.sim.device import SimulatedDevice

__all__ = ["SimulatedPtyServer"]


class SimulatedPtyServer:
    """Serve a :class:`SimulatedDevice` on a pseudo-terminal in a background thread.

    Attributes
    ----------
    url : str
        The terminal's path, to open with pyserial like any serial port.
    """

    def __init__(self, device: SimulatedDevice):
        self.device = device
        self._master, self._slave = os.openpty()
        # Raw mode: no echo of what the host writes, no newline translation.
        tty.setraw(self._slave)
        self.url = os.ttyname(self._slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="simulated-rig-pty", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.1)
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            buffer += chunk
            while b"\n" in buffer:
                raw, buffer = buffer.split(b"\n", 1)
                for reply in self.device.handle(raw.decode("ascii", errors="replace")):
                    os.write(self._master, reply.encode("ascii", errors="replace"))

    def stop(self) -> None:
        """Stop serving and close both ends."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> SimulatedPtyServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
