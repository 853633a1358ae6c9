"""Run a capture plan on the rig: Algorithm 1 of the light-stage thesis, resumable.

For each turntable position: turn; global light on, its frames, off; then for each LED: on, its
frames (an HDR bracket when the plan gives several exposures), off. A *light group* (one light at
one position) is the unit of work:

1. turn the table, unless it is known to stand at the group's angle;
2. switch the light on and wait ``settle_s``;
3. for each frame of the group not yet in place: expose; ask ``STATUS``; if the controller still
   reports the same boot id, angle and light, move the image into the session and record it;
4. switch the light off.

Why step 3 proves a frame: every reply carries the controller's boot id, which changes when it
restarts (and with it the turntable's position and the lights are lost). The ``STATUS`` reply comes
after the exposure ended; the same boot id as the ``TURN`` and switch-on acknowledgements means no
restart in between, so the image was taken as planned. A restart anywhere in the group makes the
client raise :class:`~rig.errors.DeviceReset`; the unproven image (and any late image the camera
still delivers) is set aside in ``SESSION/discarded/``, the table is turned again and the group's
missing frames retaken. Frames are recorded one by one, so a run that stops loses none of those
already proven, and a frame is recorded only once.

Any other failure (a controller that stops answering, a camera that delivers nothing) stops the
run with a :class:`~abs.errors.DeviceError` naming the port and the last command. Running the same
plan into the same folder again takes only the missing frames.
"""
from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from abs.errors import DeviceError
from rig.camera import Camera
from rig.client import RigClient
from rig.errors import DeviceReset, DeviceTimeout
from rig.plan import CapturePlan, LightGroup
from rig.session import Session

__all__ = ["run_capture", "RunResult"]


@dataclass(frozen=True)
class RunResult:
    """What one run did.

    Parameters
    ----------
    folder : Path
        The session folder.
    taken : int
        Frames taken and recorded by this run.
    already : int
        Frames that were in place before this run (a resume).
    planned : int
        Frames in the plan.
    resets : int
        Controller restarts survived (each retook one group).
    retries : int
        Commands resent after silence or a garbled line.
    """

    folder: Path
    taken: int
    already: int
    planned: int
    resets: int
    retries: int

    @property
    def complete(self) -> bool:
        return self.already + self.taken == self.planned


def _switch(client: RigClient, group: LightGroup, on: bool) -> None:
    light = group.light
    level = light.level if on else 0
    if light.kind == "global":
        client.global_light(level)
    else:
        client.led(light.board, light.led, level)


class _StateLost(Exception):
    """The rig is not in the state a frame needs (a restart, or STATUS disagrees)."""


def _verify(client: RigClient, group: LightGroup) -> None:
    """Check, after an exposure, that the rig still stands and shines as the group needs.

    The ``STATUS`` reply comes after the exposure ended; if it carries the same boot id as the
    acknowledgements of ``TURN`` and of the light's switch-on, the controller did not restart in
    between, so the image was taken in that state. It also compares the reported angle and lights
    with the plan, which catches a state changed by anything else.

    Raises
    ------
    _StateLost
        With the reason.
    """
    try:
        st = client.status()
    except DeviceReset as exc:
        raise _StateLost(f"controller restarted (boot {exc.old_boot} -> {exc.new_boot})") from exc
    light = group.light
    want_lit = {(light.board, light.led): light.level} if light.kind == "led" else {}
    want_global = light.level if light.kind == "global" else 0
    if abs(st.angle_deg - group.angle_deg) > 0.005 or st.lit != want_lit or st.global_level != want_global:
        raise _StateLost(f"STATUS reports angle {st.angle_deg:g}, global {st.global_level}, LEDs "
                         f"{st.lit}; expected {group.angle_deg:g}, {want_global}, {want_lit}")


def _set_aside(session: Session, camera: Camera, wait_s: float, pending: Path | None) -> list[Path]:
    """Move the unproven image and the camera's late images into ``SESSION/discarded/``."""
    strays = ([pending] if pending is not None else []) + camera.strays(wait_s)
    if not strays:
        return []
    folder = session.folder / "discarded"
    folder.mkdir(exist_ok=True)
    moved = []
    for path in strays:
        target = folder / path.name
        shutil.move(str(path), target)
        moved.append(target)
    return moved


def _dark_after_restart_is_fine(client: RigClient) -> None:
    """``DARK``; a restart reported on it is no failure, since a restarted controller is dark."""
    try:
        client.dark()
    except DeviceReset:
        pass


def run_capture(client: RigClient, camera: Camera, plan: CapturePlan, out: str | Path, *,
                camera_model: str = "camera", max_resets_per_group: int = 3, stray_wait_s: float = 1.0,
                log: Callable[[str], None] = lambda message: None) -> RunResult:
    """Take every frame of ``plan`` that ``out`` does not hold yet.

    Parameters
    ----------
    client : RigClient
        The controller (not yet connected: the run identifies it first).
    camera : Camera
        Trigger and drop folder.
    plan : CapturePlan
        What to take.
    out : str or Path
        Session folder, new or to resume.
    camera_model : str
        Recorded in the manifest: what made the images.
    max_resets_per_group : int
        Controller restarts tolerated while taking one group before giving up (a controller that
        restarts every few seconds has a power problem that retrying will not fix).
    stray_wait_s : float
        After a failed exposure, how long to wait for the camera's late image before setting it
        aside, seconds.
    log : callable
        Receives one line per event (progress, resets).

    Returns
    -------
    RunResult

    Raises
    ------
    DeviceError
        The controller stopped answering (:class:`~rig.errors.DeviceTimeout`), answered
        unreadably or refused a command, restarted too often, or the camera delivered no image;
        the message names the port and last command. Frames in place stay recorded.
    InputError
        ``out`` holds a session of another plan or device.
    """
    identity = client.connect()
    device = {"name": identity.name, "firmware": identity.firmware, "boards": identity.boards,
              "leds_per_board": identity.leds_per_board}
    for b, i in plan.leds:
        if b >= identity.boards or i >= identity.leds_per_board:
            raise DeviceError(f"{client.port}: the plan uses LED {i} of board {b}, but "
                              f"{identity.name} has {identity.boards} boards of "
                              f"{identity.leds_per_board} LEDs")
    session = Session.open(out, plan, device, client.port, camera_model)
    already = len(session.records)
    planned = len(plan.frames())
    taken = resets = 0
    retries_before = client.retries_used
    complete = False
    log(f"session {session.folder}: {already} of {planned} frames in place")
    try:
        _dark_after_restart_is_fine(client)
        angle: float | None = None  # unknown until we turn: a resumed rig may stand anywhere
        groups = plan.groups()
        for k, group in enumerate(groups):
            for attempt in range(max_resets_per_group + 1):
                missing = [f for f in group.frames if not session.done(f.id)]
                if not missing:
                    break
                pending: Path | None = None  # an image taken but not yet proven
                try:
                    if angle != group.angle_deg:
                        client.turn(group.angle_deg)
                        angle = group.angle_deg
                    _switch(client, group, True)
                    if plan.settle_s:
                        time.sleep(plan.settle_s)
                    for spec in missing:
                        pending = camera.capture(spec.exposure_s)
                        _verify(client, group)
                        session.commit(spec, pending, client.boot)
                        pending = None
                        taken += 1
                    _switch(client, group, False)
                    break
                except (_StateLost, DeviceReset) as exc:
                    resets += 1
                    restart = exc if isinstance(exc, DeviceReset) else exc.__cause__
                    angle = None
                    discarded = _set_aside(session, camera, stray_wait_s, pending)
                    session.event("reset", group=f"p{group.position:03d}-{group.light.name}",
                                  reason=str(exc), command=client.last_command,
                                  old_boot=getattr(restart, "old_boot", None),
                                  new_boot=getattr(restart, "new_boot", None),
                                  discarded=[p.name for p in discarded])
                    log(f"p{group.position:03d} {group.light.name}: {exc}; retaking "
                        f"({len(discarded)} image(s) set aside)")
                    _dark_after_restart_is_fine(client)
            else:
                if any(not session.done(f.id) for f in group.frames):
                    raise DeviceError(f"{client.port}: the controller lost its state "
                                      f"{max_resets_per_group + 1} times while taking "
                                      f"p{group.position:03d} {group.light.name}; check its power "
                                      f"supply (last command: {client.last_command!r})")
            if k + 1 == len(groups) or groups[k + 1].position != group.position:
                session.write_manifest(complete=False)
                log(f"position {group.position + 1}/{len(plan.angles_deg)} "
                    f"({group.angle_deg:g} deg): {len(session.records)}/{planned} frames")
        _dark_after_restart_is_fine(client)
        complete = len(session.records) == planned
    except DeviceError as exc:
        session.event("error", error=type(exc).__name__, message=str(exc),
                      last_command=client.last_command)
        if not isinstance(exc, DeviceTimeout):
            # Leave the dome dark if the controller still listens (best effort).
            try:
                client.dark()
            except DeviceError:
                pass
        raise
    except BaseException as exc:  # Ctrl-C, a bug: say so in the session before going down
        session.event("interrupted", error=type(exc).__name__, message=str(exc))
        raise
    finally:
        session.write_manifest(complete=complete)
        session.close()
    return RunResult(session.folder, taken, already, planned, resets,
                     client.retries_used - retries_before)
