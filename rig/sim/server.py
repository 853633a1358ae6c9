"""The simulated controller on a TCP socket, reachable as ``socket://127.0.0.1:PORT``.

pyserial opens that URL with the same ``serial_for_url`` call as a USB port, so the host's
transport, client and runner are the ones that drive real hardware. The device keeps its state
across connections, as a controller does when the host closes and reopens its port (a resumed
session reconnects to a rig that still holds the turntable where it was).
"""

from __future__ import annotations

import socket
import threading

from rig.sim.device import SimulatedDevice

__all__ = ["SimulatedRigServer"]


class SimulatedRigServer:
    """Serve one :class:`SimulatedDevice` on a local TCP port in a background thread.

    Parameters
    ----------
    device : SimulatedDevice
        The device logic (and its fault injection).

    Examples
    --------
    >>> with SimulatedRigServer(SimulatedDevice()) as server:   # doctest: +SKIP
    ...     transport = SerialTransport(server.url)
    """

    def __init__(self, device: SimulatedDevice):
        self.device = device
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.1)
        self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="simulated-rig", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return  # listener closed by stop()
            with conn:
                self._talk(conn)

    def _talk(self, conn: socket.socket) -> None:
        conn.settimeout(0.1)
        buffer = b""
        while not self._stop.is_set():
            try:
                chunk = conn.recv(4096)
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return
            if not chunk:
                return  # the host closed its port
            buffer += chunk
            while b"\n" in buffer:
                raw, buffer = buffer.split(b"\n", 1)
                for reply in self.device.handle(raw.decode("ascii", errors="replace")):
                    try:
                        conn.sendall(reply.encode("ascii", errors="replace"))
                    except OSError:
                        return

    def stop(self) -> None:
        """Stop serving and close the port."""
        self._stop.set()
        self._listener.close()
        self._thread.join(timeout=2.0)

    def __enter__(self) -> SimulatedRigServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
