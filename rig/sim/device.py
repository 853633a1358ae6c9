"""The device side of the rig protocol in Python: what the microcontroller's firmware does.

:class:`SimulatedDevice` turns each received line into reply lines, keeping the state a real
controller keeps (turntable angle, LED and global-light levels, the last executed line and its
reply, the boot id). :class:`Faults` injects the failures the host must survive: silence, garbled
replies and a restart in the middle of a session. The simulated camera reads the state at the
moment it is triggered, so a frame taken while a restart left the lights off really is dark.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from rig.wire import Command, Reply, WireError, format_reply, parse_command

__all__ = ["Faults", "SimulatedDevice", "DeviceState"]

FIRMWARE = "sim-1.0"


@dataclass
class Faults:
    """Failures to inject, counted in commands the device has received (1 = the first).

    Parameters
    ----------
    silent_from : int or None
        From this command on, answer nothing (a hung controller or a pulled cable), until
        :meth:`SimulatedDevice.revive`.
    garble : set of int
        Commands whose reply is corrupted on the wire (one character changed, so the checksum
        fails). A retry of the same line counts as a new command number.
    reset_at : set of int
        Commands received just after a restart: before executing them the device loses its state,
        takes a new boot id and prints its ``HELLO`` banner.
    """

    silent_from: int | None = None
    garble: set[int] = field(default_factory=set)
    reset_at: set[int] = field(default_factory=set)


@dataclass
class DeviceState:
    """What a restart loses: turntable angle (degrees) and light levels (0..255)."""

    angle_deg: float = 0.0
    global_level: int = 0
    leds: dict[tuple[int, int], int] = field(default_factory=dict)


class SimulatedDevice:
    """A light-stage controller: turntable, ``boards`` x ``leds_per_board`` LEDs, a global light.

    Parameters
    ----------
    boards, leds_per_board : int
        LED layout.
    faults : Faults, optional
        Failures to inject.
    name : str
        The name ``ID`` reports.
    on_shoot : callable, optional
        The camera on the remote-release pin.
    """

    def __init__(self, boards: int = 3, leds_per_board: int = 12, faults: Faults | None = None,
                 name: str = "sim-dome", on_shoot: Callable[[int, DeviceState], None] | None = None):
        self.on_shoot = on_shoot
        """Called as ``on_shoot(exposure_ms, state)`` when ``SHOOT`` executes: the camera wired
        to the controller's remote-release pin (see :mod:`rig.sim.camera`)."""
        self.boards = boards
        self.leds_per_board = leds_per_board
        self.faults = faults or Faults()
        self.name = name
        self.boot = 1
        self.state = DeviceState()
        self.received = 0
        """Lines received so far (the clock of :class:`Faults`)."""
        self.executed: list[str] = []
        """Bodies of the commands executed, in order (tests check nothing ran twice)."""
        self.shots: list[int] = []
        """Exposure of every ``SHOOT`` executed, milliseconds."""
        self.lock = threading.Lock()
        self._last: tuple[str, str] | None = None  # (line body, reply line) of the last execution
        self._silent = False

    def revive(self) -> None:
        """End a ``silent_from`` fault: the device answers again (someone replugged the cable)."""
        with self.lock:
            self.faults.silent_from = None
            self._silent = False

    def restart(self) -> str:
        """Lose the state and take a new boot id, as after a power glitch; returns the banner."""
        self.boot += 1
        self.state = DeviceState()
        self._last = None
        return format_reply(Reply("HELLO", 0, str(self.boot), {"name": self.name, "fw": FIRMWARE}))

    def handle(self, line: str) -> list[str]:
        """The lines the device sends in answer to one received line (possibly none)."""
        with self.lock:
            self.received += 1
            n = self.received
            out: list[str] = []
            if n in self.faults.reset_at:
                out.append(self.restart())
            if self.faults.silent_from is not None and n >= self.faults.silent_from:
                self._silent = True
            if self._silent:
                return []
            reply = self._answer(line)
            if n in self.faults.garble:
                # One character flipped in transit; the checksum no longer matches.
                i = min(3, len(reply) - 2)
                reply = reply[:i] + chr(ord(reply[i]) ^ 0x04) + reply[i + 1:]
            out.append(reply)
            return out

    def _answer(self, line: str) -> str:
        boot = str(self.boot)
        try:
            cmd = parse_command(line)
        except WireError as exc:
            reason = "checksum" if "checksum" in str(exc) else "syntax"
            return format_reply(Reply("ERR", 0, boot, reason=reason))
        if self._last is not None and self._last[0] == cmd.body:
            # The same line again: the host did not hear our reply. Answer from memory; do not
            # execute twice (docs/rig-protocol.md, "Retries").
            return self._last[1]
        try:
            fields = self._execute(cmd)
            reply = format_reply(Reply("OK", cmd.seq, boot, fields))
        except _Refusal as exc:
            reply = format_reply(Reply("ERR", cmd.seq, boot, reason=str(exc)))
        self._last = (cmd.body, reply)
        return reply

    def _int(self, text: str, low: int, high: int, what: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise _Refusal(f"syntax {what} not an integer") from None
        if not low <= value <= high:
            raise _Refusal(f"range {what} {value} outside {low}..{high}")
        return value

    def _execute(self, cmd: Command) -> dict[str, str]:
        s, a = self.state, cmd.args
        arity = {"ID": 0, "STATUS": 0, "TURN": 1, "LED": 3, "GLOBAL": 1, "DARK": 0, "SHOOT": 1}
        if cmd.name not in arity:
            raise _Refusal(f"unknown {cmd.name}")
        if len(a) != arity[cmd.name]:
            raise _Refusal(f"syntax {cmd.name} takes {arity[cmd.name]} arguments")
        self.executed.append(cmd.body)
        if cmd.name == "ID":
            return {"name": self.name, "fw": FIRMWARE, "boards": str(self.boards),
                    "leds": str(self.leds_per_board)}
        if cmd.name == "STATUS":
            lit = ",".join(f"{b}:{i}:{v}" for (b, i), v in sorted(s.leds.items()) if v) or "-"
            return {"angle": f"{s.angle_deg:.2f}", "global": str(s.global_level), "lit": lit}
        if cmd.name == "TURN":
            try:
                angle = float(a[0])
            except ValueError:
                raise _Refusal("syntax angle not a number") from None
            if not 0.0 <= angle < 360.0:
                raise _Refusal(f"range angle {angle} outside [0, 360)")
            s.angle_deg = angle
            return {"angle": f"{angle:.2f}"}
        if cmd.name == "LED":
            b = self._int(a[0], 0, self.boards - 1, "board")
            i = self._int(a[1], 0, self.leds_per_board - 1, "led")
            s.leds[(b, i)] = self._int(a[2], 0, 255, "level")
            return {}
        if cmd.name == "GLOBAL":
            s.global_level = self._int(a[0], 0, 255, "level")
            return {}
        if cmd.name == "DARK":
            s.leds.clear()
            s.global_level = 0
            return {}
        ms = self._int(a[0], 1, 600_000, "exposure_ms")  # SHOOT
        self.shots.append(ms)
        if self.on_shoot is not None:
            self.on_shoot(ms, DeviceState(s.angle_deg, s.global_level, dict(s.leds)))
        return {}

    def snapshot(self) -> DeviceState:
        """A copy of the current state (what the camera sees)."""
        with self.lock:
            return DeviceState(self.state.angle_deg, self.state.global_level, dict(self.state.leds))


class _Refusal(Exception):
    """An ``ERR`` reply: the message starts with the reason token."""
