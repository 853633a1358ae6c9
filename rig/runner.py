"""Run a capture plan on the rig: Algorithm 1 of the light-stage thesis, resumable.

For each turntable position: turn; global light on, its frames, off; then for each LED: on, its
frames (an HDR bracket when the plan gives several exposures), off. A *light group* (one light at
one position) is the unit of work:

1. turn the table if it is not known to stand at the group's angle;
2. switch the light on and wait ``settle_s``;
3. take the group's frames that are not yet in place;
4. switch the light off;
5. only now move the images into the session and record them.

Every command's acknowledgement carries the controller's boot id, so if the controller restarted
anywhere between the acknowledgement of step 2 and that of step 4, the client raises
:class:`~rig.errors.DeviceReset` before step 5: the images may have been taken in the dark or at
the home position, so they are discarded, the table is turned again and the group retaken. A
group whose step 4 was acknowledged by the same boot was lit as planned throughout.

Any other failure (a controller that stops answering, a camera that delivers nothing) stops the
run with a :class:`~abs.errors.DeviceError` naming the port and the last command. The frames in
place stay recorded; running the same plan into the same folder again takes only the missing ones.
"""

from __future__ import annotations

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


def _dark_after_restart_is_fine(client: RigClient) -> None:
    """``DARK``; a restart reported on it is no failure, since a restarted controller is dark."""
    try:
        client.dark()
    except DeviceReset:
        pass


def run_capture(client: RigClient, camera: Camera, plan: CapturePlan, out: str | Path, *,
                camera_model: str = "camera", max_resets_per_group: int = 3,
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
            missing = [f for f in group.frames if not session.done(f.id)]
            if missing:
                for attempt in range(max_resets_per_group + 1):
                    shots: list[Path] = []
                    try:
                        if angle != group.angle_deg:
                            client.turn(group.angle_deg)
                            angle = group.angle_deg
                        _switch(client, group, True)
                        if session.plan.settle_s:
                            time.sleep(session.plan.settle_s)
                        for spec in missing:
                            shots.append(camera.capture(spec.exposure_s))
                        _switch(client, group, False)
                        boot = client.boot
                    except DeviceReset as exc:
                        resets += 1
                        angle = None
                        for shot in shots:  # taken in an unknown state: not a frame of the plan
                            shot.unlink(missing_ok=True)
                        session.event("reset", group=f"p{group.position:03d}-{group.light.name}",
                                      old_boot=exc.old_boot, new_boot=exc.new_boot,
                                      command=exc.command, discarded=len(shots))
                        log(f"controller restarted during p{group.position:03d} "
                            f"{group.light.name}; retaking {len(shots)} image(s)")
                        continue
                    for spec, shot in zip(missing, shots):
                        session.commit(spec, shot, boot)
                        taken += 1
                    break
                else:
                    raise DeviceError(f"{client.port}: the controller restarted "
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
    finally:
        session.write_manifest(complete=complete)
        session.close()
    return RunResult(session.folder, taken, already, planned, resets,
                     client.retries_used - retries_before)
