"""``abs rig capture|identify``: drive the light stage over its serial line (see rig/README.md).

The hardware code lives in the top-level ``rig`` package, outside ``abs/`` (it builds on abs, not
the other way round); this command imports it only when it runs, so ``abs --help`` and every other
command work without it.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

SIMULATED_CAMERA = {
    "sphere": "simulated: textured Lambertian sphere rendered in numpy by rig.sim.optics (one ray "
              "per pixel, no noise), not abs's renderer",
    "abs": "simulated: Lambertian box rendered by abs (abs.studies.sl_capture.render_point_lit) "
           "through rig.sim.abs_optics; LED attenuation at the object's centre only, global light "
           "as a point light at the camera",
}


def add_parser(sub) -> None:
    p = sub.add_parser("rig", help="light stage: capture sessions over the rig's serial line")
    commands = p.add_subparsers(dest="rig_command", required=True)

    cap = commands.add_parser("capture", help="run a capture plan (Algorithm 1) into a session folder; "
                                              "rerun the same command to resume an interrupted session")
    cap.add_argument("--port", help="serial port or pyserial URL (/dev/ttyACM0, socket://host:port); "
                                    "not with --simulate")
    cap.add_argument("--plan", type=Path, required=True, help="capture plan (JSON, see rig/README.md)")
    cap.add_argument("--out", type=Path, required=True, help="session folder (created, or resumed)")
    cap.add_argument("--simulate", action="store_true", help="run against the simulated rig (a local "
                     "socket speaking the same protocol; its camera writes to OUT/incoming)")
    cap.add_argument("--sim-size", default="64x48", help="simulated image size WxH (default %(default)s)")
    cap.add_argument("--sim-renderer", choices=sorted(SIMULATED_CAMERA), default="sphere",
                     help="simulated frames: 'sphere', a textured Lambertian sphere in numpy "
                     "(milliseconds a frame), or 'abs', a Lambertian box rendered by abs's "
                     "point-light pass (about 0.3 s a frame at 32x24); default %(default)s")
    cap.add_argument("--sim-fault", action="append", metavar="KIND@N",
                     help="inject a fault into the simulated controller at its N-th received line: "
                     "silent@N (stops answering), garble@N (that reply garbled), reset@N (restarts "
                     "before it); repeatable")
    cap.add_argument("--sim-link", choices=("socket", "pty"), default="socket",
                     help="how the simulated controller is reached: a local socket URL or a "
                     "pseudo-terminal (POSIX); default %(default)s")
    _link_options(cap)
    cap.add_argument("--camera-folder", type=Path, help="folder the camera saves images into "
                     "(required with a real rig)")
    cap.add_argument("--trigger-command", help="trigger the camera with this program instead of the "
                     "controller's SHOOT; {exposure_s} is replaced by the exposure in seconds, e.g. "
                     "'gphoto2 --set-config shutterspeed={exposure_s} --trigger-capture'")
    cap.add_argument("--camera-timeout", type=float, default=10.0, help="wait for an image after a "
                     "trigger, seconds (default %(default)s)")
    cap.add_argument("--camera-suffix", action="append", help="only files with this suffix are images "
                     "(e.g. .cr2 when the camera saves raw+JPEG); repeatable")
    cap.set_defaults(run=run_capture)

    ident = commands.add_parser("identify", help="print the controller's identity and status")
    ident.add_argument("--port", required=True, help="serial port or pyserial URL")
    _link_options(ident)
    ident.set_defaults(run=run_identify)


def _link_options(p) -> None:
    p.add_argument("--baud", type=int, default=115200, help="baud rate (default %(default)s)")
    p.add_argument("--timeout", type=float, default=0.5,
                   help="wait for a reply, seconds (default %(default)s)")
    p.add_argument("--turn-timeout", type=float, default=10.0, help="wait for a turn to finish, "
                   "seconds (default %(default)s)")
    p.add_argument("--retries", type=int, default=3, help="resends after silence or a garbled reply "
                   "(default %(default)s)")


def _client(args, port: str):
    from rig.client import RigClient, Timing
    from rig.transport import SerialTransport

    return RigClient(SerialTransport(port, args.baud),
                     Timing(args.timeout, args.turn_timeout, retries=args.retries))


def _size(text: str) -> tuple[int, int]:
    from abs.errors import InputError

    try:
        w, h = (int(x) for x in text.lower().split("x"))
        assert w > 0 and h > 0
    except (ValueError, AssertionError):
        raise InputError(None, "--sim-size", f"expected WIDTHxHEIGHT in pixels, got {text!r}") from None
    return w, h


def _faults(specs: list[str] | None):
    from abs.errors import InputError
    from rig.sim import Faults

    faults = Faults()
    for spec in specs or []:
        kind, _, n = spec.partition("@")
        if kind not in ("silent", "garble", "reset") or not n.isdigit() or int(n) < 1:
            raise InputError(None, "--sim-fault", f"expected silent@N, garble@N or reset@N with "
                             f"N >= 1, got {spec!r}")
        if kind == "silent":
            faults.silent_from = int(n)
        else:
            (faults.garble if kind == "garble" else faults.reset_at).add(int(n))
    return faults


def _device_error(command: str, exc: Exception, resumable: bool) -> int:
    print(f"abs rig {command}: error: {exc}", file=sys.stderr)
    if resumable:
        print("the frames taken so far are recorded; run the same command again to continue",
              file=sys.stderr)
    return 3


def run_capture(args) -> int:
    from abs.errors import DeviceError, InputError
    from rig.camera import CommandTrigger, DropFolderCamera, SerialShutter
    from rig.plan import read_plan
    from rig.runner import run_capture as run

    plan = read_plan(args.plan)
    suffixes = tuple(s.lower() if s.startswith(".") else "." + s.lower()
                     for s in args.camera_suffix) if args.camera_suffix else None
    sim = None
    if args.simulate:
        if args.port:
            raise InputError(None, "--port", "not with --simulate (the simulated rig has its own port)")
        from rig.sim import SimulatedRig

        width, height = _size(args.sim_size)
        boards = max([b for b, _ in plan.leds], default=0) + 1
        per_board = max([i for _, i in plan.leds], default=0) + 1
        sim = SimulatedRig(args.out / "incoming", boards, per_board, width, height,
                           faults=_faults(args.sim_fault), renderer=args.sim_renderer,
                           link=args.sim_link)
        port, folder, model = sim.url, args.out / "incoming", SIMULATED_CAMERA[args.sim_renderer]
        if args.sim_renderer == "sphere":
            # The simulated rig knows its geometry exactly: write it for 'abs lightstage'.
            from rig.sim.lightstage_files import write_lightstage_files

            write_lightstage_files(sim.dome, width, height, args.out)
    else:
        if not args.port:
            raise InputError(None, "--port", "required (or --simulate)")
        if args.camera_folder is None:
            raise InputError(None, "--camera-folder", "required with a real rig: the folder the "
                             "camera saves its images into")
        if args.sim_fault:
            raise InputError(None, "--sim-fault", "only with --simulate")
        port, folder, model = args.port, args.camera_folder, "camera"
    try:
        client = _client(args, port)
        try:
            trigger = (CommandTrigger(shlex.split(args.trigger_command)) if args.trigger_command
                       else SerialShutter(client))
            camera = DropFolderCamera(folder, trigger, args.camera_timeout, suffixes=suffixes)
            result = run(client, camera, plan, args.out, camera_model=model, log=print)
        finally:
            client.close()
    except DeviceError as exc:
        return _device_error("capture", exc, resumable=(args.out / "manifest.json").exists())
    finally:
        if sim is not None:
            sim.close()
    print(f"{args.out}: {result.already + result.taken}/{result.planned} frames "
          f"({result.taken} taken now, {result.already} before; {result.resets} controller "
          f"restart(s), {result.retries} resent command(s))")
    return 0


def run_identify(args) -> int:
    from abs.errors import DeviceError

    try:
        client = _client(args, args.port)
        try:
            who = client.connect()
            st = client.status()
        finally:
            client.close()
    except DeviceError as exc:
        return _device_error("identify", exc, resumable=False)
    lit = ", ".join(f"board {b} led {i}: {v}" for (b, i), v in sorted(st.lit.items())) or "none"
    print(f"{args.port}: {who.name}, firmware {who.firmware}, {who.boards} boards x "
          f"{who.leds_per_board} LEDs, boot {who.boot}")
    print(f"turntable {st.angle_deg:g} deg, global light {st.global_level}, LEDs on: {lit}")
    return 0
