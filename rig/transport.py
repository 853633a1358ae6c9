"""Byte lines over a serial port, through pyserial's ``serial_for_url``.

``serial_for_url`` opens real ports (``/dev/ttyACM0``, ``COM3``), pseudo-terminals
(``/dev/pts/7``) and pyserial's URL handlers (``loop://``, ``socket://host:port``,
``rfc2217://``) with one API, so the same host code drives the microcontroller, the simulated rig
on a socket and the loop-back device of a unit test.
"""

from __future__ import annotations

import time
from typing import Protocol

import serial

from abs.errors import DeviceError

__all__ = ["LineTransport", "SerialTransport", "DEFAULT_BAUD"]

DEFAULT_BAUD = 115200
"""Baud rate of the rig controller's USB serial port (docs/rig-protocol.md)."""


class LineTransport(Protocol):
    """What the protocol client needs from a link: whole lines in and out."""

    port: str

    def write_line(self, line: str) -> None:
        """Send one line (it already ends with ``\\n``)."""

    def read_line(self, timeout_s: float) -> str | None:
        """The next whole line, without waiting longer than ``timeout_s`` seconds; ``None`` on
        timeout (a partial line is kept for the next call)."""

    def discard_input(self) -> None:
        """Drop everything received and not yet read (stale replies before a retry)."""

    def close(self) -> None:
        """Release the port."""


class SerialTransport:
    """A :class:`LineTransport` over a pyserial port.

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    baudrate : int
        Bits per second (ignored by ``socket://`` and ``loop://``).
    poll_s : float
        Longest single blocking read, seconds: reads are chopped into slices this long so that a
        line's deadline is honoured to within it.

    Raises
    ------
    DeviceError
        If the port cannot be opened (the message names it).
    """

    def __init__(self, port: str, baudrate: int = DEFAULT_BAUD, poll_s: float = 0.05):
        self.port = port
        try:
            self._serial = serial.serial_for_url(port, baudrate=baudrate, timeout=poll_s,
                                                 write_timeout=2.0)
        except (serial.SerialException, ValueError, OSError) as exc:
            raise DeviceError(f"{port}: cannot open the port: {exc}") from exc
        self._buffer = bytearray()

    def write_line(self, line: str) -> None:
        try:
            self._serial.write(line.encode("ascii"))
            self._serial.flush()
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"{self.port}: cannot write {line.strip()!r}: {exc}") from exc

    def read_line(self, timeout_s: float) -> str | None:
        deadline = time.monotonic() + timeout_s
        while True:
            newline = self._buffer.find(b"\n")
            if newline >= 0:
                raw = bytes(self._buffer[:newline + 1])
                del self._buffer[:newline + 1]
                # Line noise can produce any byte; undecodable bytes become U+FFFD and then fail
                # the checksum, which is how the client learns the reply was garbled.
                return raw.decode("ascii", errors="replace")
            if time.monotonic() >= deadline:
                return None
            try:
                chunk = self._serial.read(max(1, self._serial.in_waiting))
            except (serial.SerialException, OSError) as exc:
                raise DeviceError(f"{self.port}: cannot read: {exc}") from exc
            self._buffer += chunk

    def discard_input(self) -> None:
        self._buffer.clear()
        try:
            self._serial.reset_input_buffer()
        except (serial.SerialException, OSError):
            pass  # nothing to discard on a closed link; the next read reports the failure

    def close(self) -> None:
        self._serial.close()
