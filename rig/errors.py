"""The ways a rig can fail, each a :class:`abs.errors.DeviceError` that names the port.

Every message says which port and which command, because the person reading it is standing
next to a rig with several USB cables and has to know which one to check.
"""

from __future__ import annotations

from abs.errors import DeviceError

__all__ = ["DeviceError", "DeviceTimeout", "DeviceGarbled", "DeviceRefused", "DeviceReset",
           "CameraError"]


class _PortError(DeviceError):
    """A device error about one command on one port.

    Parameters
    ----------
    port : str
        The serial port or URL (``/dev/ttyACM0``, ``socket://127.0.0.1:5000``).
    command : str
        The last command sent, as on the wire without checksum (``17 LED 2 5 255``).
    message : str
        What happened.
    """

    def __init__(self, port: str, command: str, message: str):
        self.port = port
        self.command = command
        super().__init__(f"{port}: {message} (last command: {command!r})")


class DeviceTimeout(_PortError):
    """The device did not answer a command within its timeout, after every retry."""


class DeviceGarbled(_PortError):
    """Every attempt at a command got a reply that failed its checksum or did not parse."""


class DeviceRefused(_PortError):
    """The device answered ``ERR`` with a reason that a retry cannot fix (range, syntax, fault)."""


class DeviceReset(_PortError):
    """The device's boot id changed: it restarted and lost its state (turntable position, lights).

    The command named was executed *after* the restart. ``old_boot`` and ``new_boot`` are the
    two ids.
    """

    def __init__(self, port: str, command: str, old_boot: str, new_boot: str):
        self.old_boot = old_boot
        self.new_boot = new_boot
        super().__init__(port, command, f"device restarted (boot id {old_boot} -> {new_boot}); "
                                        "its turntable position and lights were lost")


class CameraError(DeviceError):
    """The camera did not deliver an image file in time, or delivered something unusable."""
