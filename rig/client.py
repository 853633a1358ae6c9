"""The host side of the rig protocol: numbered commands, acknowledgements, timeouts and retries.

A command is sent as ``<seq> <NAME> [args]*HH``. The client waits for the ``OK``/``ERR`` with the
same sequence number; replies with other numbers are late answers to earlier attempts and are
skipped. On silence or a garbled reply it resends the *same line*: the device remembers the last
line it executed and answers a repeat from memory without executing it again (docs/rig-protocol.md,
"Retries"), so a retried ``SHOOT`` fires the camera once.

Every reply carries the device's boot id. A new one means the device restarted and lost its
state; the client raises :class:`~rig.errors.DeviceReset` so the capture runner can restore the
turntable and lights before it trusts another frame.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass

from rig.errors import DeviceGarbled, DeviceRefused, DeviceReset, DeviceTimeout
from rig.transport import LineTransport
from rig.wire import Command, Reply, WireError, format_command, parse_reply

__all__ = ["RigClient", "Identity", "RigStatus", "Timing"]


@dataclass(frozen=True)
class Timing:
    """How long to wait and how often to try.

    Parameters
    ----------
    timeout_s : float
        Wait for one reply, seconds (lights and queries answer within milliseconds).
    turn_timeout_s : float
        Wait for a ``TURN`` reply, seconds: the device acknowledges a turn when the table has
        stopped, which takes up to a few seconds for half a revolution on a servo.
    shoot_margin_s : float
        Added to the exposure time for a ``SHOOT`` reply, seconds.
    retries : int
        Extra attempts after the first (so ``retries + 1`` sends of the same line at most).
    """

    timeout_s: float = 0.5
    turn_timeout_s: float = 10.0
    shoot_margin_s: float = 0.5
    retries: int = 3


@dataclass(frozen=True)
class Identity:
    """The answer to ``ID``: device name, firmware, how many LED boards and LEDs per board."""

    name: str
    firmware: str
    boards: int
    leds_per_board: int
    boot: str


@dataclass(frozen=True)
class RigStatus:
    """The answer to ``STATUS``.

    Parameters
    ----------
    angle_deg : float
        Turntable angle, degrees in [0, 360).
    global_level : int
        Global light level, 0 (off) .. 255.
    lit : dict of (int, int) to int
        Level of every LED that is on, by (board, led).
    boot : str
        Boot id.
    """

    angle_deg: float
    global_level: int
    lit: dict[tuple[int, int], int]
    boot: str


class RigClient:
    """Commands to the rig controller over a line transport.

    Parameters
    ----------
    transport : LineTransport
        The link (usually :class:`~rig.transport.SerialTransport`).
    timing : Timing
        Timeouts and retries.
    first_seq : int, optional
        Sequence number of the first command; random by default, so that a host restarted in the
        middle of a session does not send its first line with the same number the device
        remembers from the previous run (see docs/rig-protocol.md, "Retries").
    """

    def __init__(self, transport: LineTransport, timing: Timing = Timing(), first_seq: int | None = None):
        self.transport = transport
        self.timing = timing
        self._seq = (first_seq if first_seq is not None else random.randint(1, 65535)) - 1
        self.boot: str | None = None
        self.last_command = "(none)"
        self.retries_used = 0
        """Attempts beyond the first over the client's life (for the session log)."""

    @property
    def port(self) -> str:
        return self.transport.port

    def _next_seq(self) -> int:
        # Wraps 65535 -> 1; 0 is reserved for the device's "ERR 0" about unreadable lines.
        self._seq = self._seq % 65535 + 1
        return self._seq

    def command(self, name: str, *args: object, timeout_s: float | None = None) -> Reply:
        """Send one command and return its ``OK`` reply.

        Parameters
        ----------
        name : str
            Command word.
        *args
            Arguments, formatted with ``str``.
        timeout_s : float, optional
            Wait per attempt, seconds (default ``timing.timeout_s``).

        Raises
        ------
        DeviceTimeout
            No reply to any of the ``retries + 1`` attempts.
        DeviceGarbled
            Replies came but none passed its checksum and parsed.
        DeviceRefused
            ``ERR`` with a reason other than ``checksum`` (retrying cannot help).
        DeviceReset
            The reply's boot id differs from the one seen before; the command was executed by
            the restarted device.
        """
        cmd = Command(self._next_seq(), name.upper(), tuple(str(a) for a in args))
        line = format_command(cmd)
        self.last_command = cmd.body
        wait = self.timing.timeout_s if timeout_s is None else timeout_s
        garbled: list[str] = []
        for attempt in range(self.timing.retries + 1):
            if attempt:
                self.retries_used += 1
            self.transport.write_line(line)
            reply = self._await(cmd.seq, wait, garbled)
            if reply is None:
                continue
            if reply.kind == "ERR" and reply.reason.split()[0:1] == ["checksum"]:
                continue  # the device read our line garbled: the same line again
            self._check_boot(reply)
            if reply.kind == "ERR":
                raise DeviceRefused(self.port, cmd.body, f"device refused: {reply.reason}")
            return reply
        if garbled:
            raise DeviceGarbled(self.port, cmd.body, f"no readable reply in {self.timing.retries + 1} "
                                f"attempts; last garbled line {garbled[-1]!r}")
        raise DeviceTimeout(self.port, cmd.body, f"device stopped answering: no reply in "
                            f"{self.timing.retries + 1} attempts of {wait:g} s each")

    def _await(self, seq: int, wait: float, garbled: list[str]) -> Reply | None:
        """The reply to ``seq`` within ``wait`` seconds, or ``None`` (silence or garbage)."""
        deadline = time.monotonic() + wait
        while (left := deadline - time.monotonic()) > 0:
            line = self.transport.read_line(left)
            if line is None:
                return None
            try:
                reply = parse_reply(line)
            except WireError:
                garbled.append(line.rstrip("\r\n"))
                # Resend at once rather than wait out the timeout: the device is alive.
                return None
            if reply.kind == "HELLO":
                continue  # the start-up banner; a changed boot id is caught on the reply itself
            if reply.seq == seq or (reply.kind == "ERR" and reply.seq == 0):
                return reply
            # A different number: a late reply to an earlier attempt or command. Skip it.
        return None

    def _check_boot(self, reply: Reply) -> None:
        if self.boot is not None and reply.boot != self.boot:
            old, self.boot = self.boot, reply.boot
            raise DeviceReset(self.port, self.last_command, old, reply.boot)
        self.boot = reply.boot

    # -- the commands of docs/rig-protocol.md --------------------------------------------------

    def identify(self) -> Identity:
        """``ID``: name, firmware and LED layout of the controller."""
        r = self.command("ID")
        try:
            return Identity(r.fields["name"], r.fields["fw"], int(r.fields["boards"]),
                            int(r.fields["leds"]), r.boot)
        except (KeyError, ValueError) as exc:
            raise DeviceGarbled(self.port, self.last_command, f"ID reply lacks name/fw/boards/leds: "
                                f"{r.fields}") from exc

    def status(self) -> RigStatus:
        """``STATUS``: turntable angle and which lights are on."""
        r = self.command("STATUS")
        try:
            lit = {}
            for item in filter(None, r.fields.get("lit", "-").split(",")):
                if item == "-":
                    continue
                b, led, level = (int(x) for x in item.split(":"))
                lit[(b, led)] = level
            return RigStatus(float(r.fields["angle"]), int(r.fields["global"]), lit, r.boot)
        except (KeyError, ValueError) as exc:
            raise DeviceGarbled(self.port, self.last_command, f"STATUS reply unreadable: {r.fields}") from exc

    def turn(self, angle_deg: float) -> None:
        """``TURN``: move the turntable to an absolute angle (degrees, 0.01 degree resolution) and
        return once it has stopped."""
        self.command("TURN", f"{angle_deg % 360.0:.2f}", timeout_s=self.timing.turn_timeout_s)

    def led(self, board: int, led: int, level: int) -> None:
        """``LED``: set one LED's level, 0 (off) .. 255 (full)."""
        self.command("LED", int(board), int(led), int(level))

    def global_light(self, level: int) -> None:
        """``GLOBAL``: set the global (photogrammetry) light's level, 0 .. 255."""
        self.command("GLOBAL", int(level))

    def dark(self) -> None:
        """``DARK``: every LED and the global light off."""
        self.command("DARK")

    def shoot(self, exposure_s: float) -> None:
        """``SHOOT``: hold the camera's remote-release line for ``exposure_s`` seconds (bulb
        mode) and return when the exposure has ended."""
        ms = max(1, int(round(exposure_s * 1000.0)))
        self.command("SHOOT", ms, timeout_s=exposure_s + self.timing.shoot_margin_s)

    def connect(self) -> Identity:
        """Drop stale input and identify the device, learning its boot id."""
        self.transport.discard_input()
        return self.identify()

    def close(self) -> None:
        self.transport.close()
