"""Capture plans: which turntable positions, lights and exposures a session takes.

A plan is a JSON file (format in rig/README.md and docs/rig-protocol.md, "Capture plans"). It
expands into the thesis's Algorithm 1: at every turntable position, the global light's frames for
photogrammetry, then every LED's frames (an HDR bracket when several exposures are given). Every
frame gets a stable id from its position, light and exposure index, so a resumed session can tell
which frames it already has.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from abs.errors import InputError, read_json

__all__ = ["CapturePlan", "Light", "LightGroup", "FrameSpec", "read_plan", "plan_from_dict"]


@dataclass(frozen=True)
class Light:
    """One light condition: the global light, or LED ``led`` on board ``board``, at ``level``
    (0..255 of full power)."""

    kind: str  # "global" or "led"
    level: int
    board: int = -1
    led: int = -1

    @property
    def name(self) -> str:
        """``global`` or ``b02l07``: the part of a frame id that names the light."""
        return "global" if self.kind == "global" else f"b{self.board:02d}l{self.led:02d}"


@dataclass(frozen=True)
class FrameSpec:
    """One frame of the plan.

    Parameters
    ----------
    id : str
        ``p003-b01l04-e2``: position index, light, exposure index (the file's stem).
    position : int
        Turntable position index.
    angle_deg : float
        Turntable angle, degrees.
    light : Light
        The light that is on (and no other).
    exposure_index : int
        Index in the light's bracket.
    exposure_s : float
        Exposure time, seconds.
    """

    id: str
    position: int
    angle_deg: float
    light: Light
    exposure_index: int
    exposure_s: float


@dataclass(frozen=True)
class LightGroup:
    """The frames taken under one light at one position: switch on, capture each, switch off."""

    position: int
    angle_deg: float
    light: Light
    frames: tuple[FrameSpec, ...]


@dataclass(frozen=True)
class CapturePlan:
    """A normalised plan (see :func:`plan_from_dict`).

    Parameters
    ----------
    angles_deg : tuple of float
        Turntable angles, degrees in [0, 360), in capture order.
    global_level : int
        Global light level for the photogrammetry frames; 0 for none.
    global_exposures_s : tuple of float
        Exposures of the global-light frames, seconds.
    leds : tuple of (int, int)
        (board, led) of each LED, in capture order.
    led_level : int
        Level of every LED frame, 0..255.
    exposures_s : tuple of float
        The bracket taken under each LED, seconds.
    settle_s : float
        Wait after switching a light on before the first exposure, seconds (LED driver rise,
        turntable wobble).
    """

    angles_deg: tuple[float, ...]
    global_level: int
    global_exposures_s: tuple[float, ...]
    leds: tuple[tuple[int, int], ...]
    led_level: int
    exposures_s: tuple[float, ...]
    settle_s: float = 0.0

    def groups(self) -> list[LightGroup]:
        """Algorithm 1 in order: per position, the global light's group, then each LED's group."""
        out = []
        for p, angle in enumerate(self.angles_deg):
            lights: list[tuple[Light, tuple[float, ...]]] = []
            if self.global_level > 0 and self.global_exposures_s:
                lights.append((Light("global", self.global_level), self.global_exposures_s))
            lights += [(Light("led", self.led_level, b, i), self.exposures_s) for b, i in self.leds]
            for light, exposures in lights:
                frames = tuple(FrameSpec(f"p{p:03d}-{light.name}-e{k}", p, angle, light, k, e)
                               for k, e in enumerate(exposures))
                out.append(LightGroup(p, angle, light, frames))
        return out

    def frames(self) -> list[FrameSpec]:
        """Every frame of the plan, in capture order."""
        return [f for g in self.groups() for f in g.frames]

    def to_dict(self) -> dict[str, Any]:
        """The normalised plan as JSON-ready data (stored in the manifest; a resumed session
        must be given a plan with the same normal form)."""
        return {"angles_deg": list(self.angles_deg),
                "global_light": {"level": self.global_level,
                                 "exposures_s": list(self.global_exposures_s)},
                "leds": [list(x) for x in self.leds], "led_level": self.led_level,
                "exposures_s": list(self.exposures_s), "settle_s": self.settle_s}


def _number(source: Any, field: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        raise InputError(source, field, f"expected a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def _integer(source: Any, field: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(source, field, f"expected an integer in {low}..{high}, got {value!r}")
    return value


def _exposures(source: Any, field: str, value: Any) -> tuple[float, ...]:
    if not isinstance(value, list) or not value:
        raise InputError(source, field, f"expected a non-empty list of exposure times in seconds, "
                                        f"got {value!r}")
    return tuple(_number(source, f"{field}[{i}]", e, 1e-6, 600.0) for i, e in enumerate(value))


def plan_from_dict(data: dict[str, Any], source: str | Path | None = None) -> CapturePlan:
    """Validate and normalise a plan.

    Parameters
    ----------
    data : dict
        The decoded plan file.
    source : str or Path, optional
        The file it came from, for error messages.

    Raises
    ------
    InputError
        Naming the file and field of any missing or malformed value.
    """
    known = {"turntable", "global_light", "leds", "led_level", "exposures_s", "settle_s"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(source, unknown[0], f"unknown field; expected some of {sorted(known)}")
    table = data.get("turntable")
    if not isinstance(table, dict):
        raise InputError(source, "turntable", 'expected {"positions": N} or {"angles_deg": [...]}')
    if "angles_deg" in table:
        raw = table["angles_deg"]
        if not isinstance(raw, list) or not raw:
            raise InputError(source, "turntable.angles_deg", "expected a non-empty list of degrees")
        # Rounded to the protocol's 0.01 degree (TURN takes two decimals), so that the angle
        # STATUS reports compares equal to the planned one; 359.996 rounds to 0.
        angles = tuple(round(_number(source, f"turntable.angles_deg[{i}]", a, 0.0, 360.0), 2)
                       % 360.0 for i, a in enumerate(raw))
    elif "positions" in table:
        n = _integer(source, "turntable.positions", table["positions"], 1, 36000)
        angles = tuple(round(360.0 * k / n, 2) for k in range(n))
    else:
        raise InputError(source, "turntable", 'expected "positions" or "angles_deg"')
    if len(set(angles)) != len(angles):
        raise InputError(source, "turntable", "an angle appears twice (at 0.01 degree resolution)")

    glob = data.get("global_light")
    if glob is None:
        global_level, global_exposures = 0, ()
    elif isinstance(glob, dict):
        global_level = _integer(source, "global_light.level", glob.get("level", 255), 1, 255)
        global_exposures = _exposures(source, "global_light.exposures_s", glob.get("exposures_s"))
    else:
        raise InputError(source, "global_light", 'expected {"level": 1..255, "exposures_s": [...]} or null')

    raw_leds = data.get("leds", [])
    if isinstance(raw_leds, dict):
        boards = _integer(source, "leds.boards", raw_leds.get("boards"), 1, 64)
        per = _integer(source, "leds.leds_per_board", raw_leds.get("leds_per_board"), 1, 256)
        leds = tuple((b, i) for b in range(boards) for i in range(per))
    elif isinstance(raw_leds, list):
        pairs = []
        for k, item in enumerate(raw_leds):
            if not (isinstance(item, list) and len(item) == 2):
                raise InputError(source, f"leds[{k}]", f"expected [board, led], got {item!r}")
            pairs.append((_integer(source, f"leds[{k}][0]", item[0], 0, 63),
                          _integer(source, f"leds[{k}][1]", item[1], 0, 255)))
        leds = tuple(pairs)
    else:
        raise InputError(source, "leds", 'expected [[board, led], ...] or {"boards": B, "leds_per_board": L}')
    if len(set(leds)) != len(leds):
        raise InputError(source, "leds", "an LED appears twice")
    led_level = _integer(source, "led_level", data.get("led_level", 255), 1, 255)
    if leds and "exposures_s" not in data:
        raise InputError(source, "exposures_s", "required when the plan has LEDs")
    exposures = _exposures(source, "exposures_s", data["exposures_s"]) if leds else ()
    if not leds and global_level == 0:
        raise InputError(source, "leds", "the plan takes no frames: give LEDs or a global_light")
    settle = _number(source, "settle_s", data.get("settle_s", 0.0), 0.0, 60.0)
    return CapturePlan(angles, global_level, global_exposures, leds, led_level, exposures, settle)


def read_plan(path: str | Path) -> CapturePlan:
    """Read and validate a plan file (see :func:`plan_from_dict`)."""
    return plan_from_dict(read_json(path, what="capture plan"), path)
