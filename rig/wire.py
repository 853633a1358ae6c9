"""The line format of the rig protocol (docs/rig-protocol.md), shared by host and device.

One message is one ASCII line ``BODY*HH\\n``: ``HH`` is the XOR of every byte of ``BODY`` as two
upper-case hex digits (the NMEA 0183 checksum). A serial line at 115200 baud with a long USB cable
flips bits now and then; without the checksum a flipped digit in ``OK 12`` would read as a valid
acknowledgement of command 13. Pure functions only: no I/O, so the simulated device and the host
parse with exactly the same code.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["MAX_LINE", "Command", "Reply", "WireError", "checksum", "frame", "unframe",
           "format_command", "parse_command", "format_reply", "parse_reply"]

MAX_LINE = 120
"""Longest line either side sends, bytes without the newline (a microcontroller's line buffer)."""


class WireError(ValueError):
    """A line that is not a well-formed protocol message (bad checksum, syntax, length)."""


def checksum(body: str) -> str:
    """The two-hex-digit XOR checksum of ``body`` (ASCII)."""
    value = 0
    for byte in body.encode("ascii"):
        value ^= byte
    return f"{value:02X}"


def frame(body: str) -> str:
    """``body`` as a line on the wire: ``BODY*HH\\n``.

    Raises
    ------
    WireError
        If ``body`` is not printable ASCII, contains ``*`` or is longer than :data:`MAX_LINE`.
    """
    if not body.isascii() or not body.isprintable() or "*" in body:
        raise WireError(f"not a printable ASCII message without '*': {body!r}")
    line = f"{body}*{checksum(body)}"
    if len(line) > MAX_LINE:
        raise WireError(f"message longer than {MAX_LINE} bytes: {line!r}")
    return line + "\n"


def unframe(line: str) -> str:
    """The body of a received line, its checksum verified (trailing ``\\r``/``\\n`` ignored).

    Raises
    ------
    WireError
        If the line has no ``*HH`` suffix or the checksum does not match.
    """
    text = line.rstrip("\r\n")
    body, star, given = text.rpartition("*")
    if not star or len(given) != 2:
        raise WireError(f"no checksum: {text!r}")
    if not body.isascii() or given.upper() != checksum(body):
        raise WireError(f"checksum mismatch: {text!r}")
    return body


@dataclass(frozen=True)
class Command:
    """A host command: ``<seq> <NAME> [args...]``.

    Parameters
    ----------
    seq : int
        Sequence number, 1..65535; a retry resends the same number (and the same line).
    name : str
        Upper-case command word (``ID``, ``STATUS``, ``TURN``, ``LED``, ``GLOBAL``, ``DARK``, ``SHOOT``).
    args : tuple of str
        The arguments as sent.
    """

    seq: int
    name: str
    args: tuple[str, ...] = ()

    @property
    def body(self) -> str:
        return " ".join([str(self.seq), self.name, *self.args])


@dataclass(frozen=True)
class Reply:
    """A device reply: ``OK <seq> boot=<id> [key=value...]``, ``ERR <seq> boot=<id> <reason>
    [text...]`` or the unsolicited start-up banner ``HELLO boot=<id> [key=value...]``.

    Parameters
    ----------
    kind : str
        ``"OK"``, ``"ERR"`` or ``"HELLO"``.
    seq : int
        The command's sequence number (0 for ``HELLO``, and for ``ERR 0`` about a line the device
        could not read at all).
    boot : str
        The device's boot id: it changes at every power-up or reset, so a host that sees a new one
        knows the device lost its state (turntable position, lights).
    fields : dict of str to str
        The ``key=value`` fields after the boot id.
    reason : str
        For ``ERR``: the reason token (``checksum``, ``syntax``, ``unknown``, ``range``, ``fault``)
        followed by any free text.
    """

    kind: str
    seq: int
    boot: str
    fields: dict[str, str] = field(default_factory=dict)
    reason: str = ""


def format_command(command: Command) -> str:
    """The wire line of a command."""
    return frame(command.body)


def parse_command(line: str) -> Command:
    """A command from its wire line (device side).

    Raises
    ------
    WireError
        Bad checksum or a line that is not ``<seq> <NAME> [args]``.
    """
    parts = unframe(line).split()
    if len(parts) < 2 or not parts[0].isdigit() or not 1 <= int(parts[0]) <= 65535:
        raise WireError(f"expected '<seq 1..65535> <COMMAND> [args]', got {line.strip()!r}")
    return Command(int(parts[0]), parts[1].upper(), tuple(parts[2:]))


def format_reply(reply: Reply) -> str:
    """The wire line of a reply (device side)."""
    head = [reply.kind] if reply.kind == "HELLO" else [reply.kind, str(reply.seq)]
    parts = head + [f"boot={reply.boot}"] + [f"{k}={v}" for k, v in reply.fields.items()]
    if reply.kind == "ERR":
        parts.append(reply.reason)
    return frame(" ".join(parts))


def parse_reply(line: str) -> Reply:
    """A reply from its wire line (host side).

    Raises
    ------
    WireError
        Bad checksum, an unknown reply kind, a missing sequence number or boot id.
    """
    parts = unframe(line).split()
    if not parts or parts[0] not in ("OK", "ERR", "HELLO"):
        raise WireError(f"expected OK, ERR or HELLO, got {line.strip()!r}")
    kind, rest = parts[0], parts[1:]
    seq = 0
    if kind != "HELLO":
        if not rest or not rest[0].isdigit():
            raise WireError(f"{kind} without a sequence number: {line.strip()!r}")
        seq, rest = int(rest[0]), rest[1:]
    if not rest or not rest[0].startswith("boot="):
        raise WireError(f"{kind} without boot=<id>: {line.strip()!r}")
    boot, rest = rest[0][5:], rest[1:]
    fields: dict[str, str] = {}
    while rest and "=" in rest[0]:
        key, _, value = rest.pop(0).partition("=")
        fields[key] = value
    return Reply(kind, seq, boot, fields, " ".join(rest) if kind == "ERR" else "")
