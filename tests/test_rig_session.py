"""Capture sessions on the simulated rig: Algorithm 1 end to end over the real serial code, a
controller restart in mid-session, and resume after a crash with no frame lost or taken twice
(checked from manifest.json, the files and the simulated controller's shutter count)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from abs.errors import InputError
from abs.io.images import read_image
from rig.camera import DropFolderCamera, SerialShutter
from rig.client import RigClient, Timing
from rig.errors import DeviceTimeout
from rig.plan import plan_from_dict, read_plan
from rig.runner import run_capture
from rig.session import Session
from rig.sim import Faults, SimulatedRig, render_frame
from rig.transport import SerialTransport

FAST = Timing(timeout_s=0.15, turn_timeout_s=0.3, shoot_margin_s=0.2, retries=2)
W, H = 32, 24
PLAN = {"turntable": {"positions": 3}, "global_light": {"level": 200, "exposures_s": [0.02]},
        "leds": {"boards": 2, "leds_per_board": 2}, "exposures_s": [0.01, 0.04]}
# 3 positions x (1 global + 4 LEDs x 2 exposures) = 27 frames.


def _run(sim: SimulatedRig, out: Path, plan=None):
    client = RigClient(SerialTransport(sim.url), FAST)
    camera = DropFolderCamera(out / "incoming", SerialShutter(client), timeout_s=2.0)
    try:
        # The simulated camera writes its image before SHOOT is acknowledged: no late images.
        return run_capture(client, camera, plan or plan_from_dict(PLAN), out, stray_wait_s=0.0)
    finally:
        client.close()


def _check_session(out: Path, sim: SimulatedRig) -> dict:
    """Every planned frame once in the manifest, exactly the recorded files in frames/, and each
    image the one the planned turntable angle and light produce (not one taken in the dark)."""
    plan = plan_from_dict(PLAN)
    manifest = json.loads((out / "manifest.json").read_text())
    ids = [f["id"] for f in manifest["frames"]]
    assert ids == [f.id for f in plan.frames()]  # all, once each, in plan order
    assert manifest["complete"] and manifest["frames_in_place"] == len(ids)
    assert sorted(p.name for p in (out / "frames").iterdir()) == sorted(
        Path(f["file"]).name for f in manifest["frames"])
    for spec, record in zip(plan.frames(), manifest["frames"]):
        light = spec.light
        leds = {(light.board, light.led): light.level} if light.kind == "led" else {}
        expected = render_frame(sim.dome, W, H, spec.angle_deg,
                                light.level if light.kind == "global" else 0, leds, spec.exposure_s)
        np.testing.assert_allclose(read_image(out / record["file"]), expected, atol=1e-6)
    return manifest


def test_a_full_session_runs_algorithm_1(tmp_path):
    with SimulatedRig(tmp_path / "incoming", 2, 2, W, H) as sim:
        result = _run(sim, tmp_path)
        shots = list(sim.device.shots)
        order = [c.split()[1] for c in sim.device.executed if "STATUS" not in c]
        statuses = sum("STATUS" in c for c in sim.device.executed)
    assert result.complete and (result.taken, result.already, result.planned) == (27, 0, 27)
    _check_session(tmp_path, sim)
    assert shots == [20, 10, 40, 10, 40, 10, 40, 10, 40] * 3  # each frame fired once
    # Algorithm 1 at the first position: turn, global on, shoot, off, then per LED on, bracket, off.
    assert order[:8] == ["ID", "DARK", "TURN", "GLOBAL", "SHOOT", "GLOBAL", "LED", "SHOOT"]
    assert statuses == 27  # every frame proven by a STATUS after its exposure
    assert not list((tmp_path / "incoming").iterdir())  # every image moved into the session


@pytest.mark.parametrize("at, dark", [(17, True), (16, False)])
def test_a_controller_restart_mid_session_is_survived(tmp_path, at, dark):
    """Commands at position 0: 1 ID, 2 DARK, 3 TURN, 4 GLOBAL, 5 SHOOT, 6 STATUS, 7 GLOBAL 0,
    8-13 LED b00l00 (on, SHOOT, STATUS, SHOOT, STATUS, off), 14 LED b00l01 on, 15 SHOOT, 16 STATUS,
    17 SHOOT. A restart before 17 makes that exposure in the dark; a restart before 16 comes
    after a good exposure that can no longer be proven. Either image is set aside and retaken."""
    with SimulatedRig(tmp_path / "incoming", 2, 2, W, H, faults=Faults(reset_at={at})) as sim:
        result = _run(sim, tmp_path)
        shots = len(sim.device.shots)
    assert result.complete and result.resets == 1 and result.taken == 27
    assert shots == 28  # the set-aside exposure, and 27 frames
    manifest = _check_session(tmp_path, sim)
    reset = [e for e in manifest["events"] if e["event"] == "reset"]
    assert len(reset) == 1 and (reset[0]["old_boot"], reset[0]["new_boot"]) == ("1", "2")
    assert reset[0]["group"] == "p000-b00l01" and len(reset[0]["discarded"]) == 1
    aside = read_image(tmp_path / "discarded" / reset[0]["discarded"][0])
    assert (aside.max() == 0.0) == dark  # the restart switched the LED off before the shutter
    boots = {f["id"]: f["device_boot"] for f in manifest["frames"]}
    assert boots["p000-b00l01-e0"] == ("1" if dark else "2") and boots["p000-b00l01-e1"] == "2"


def test_kill_and_resume_loses_and_duplicates_nothing(tmp_path):
    # The controller stops answering at its 38th command, the first LED's first SHOOT at position
    # 1 (31 commands for position 0, then TURN, GLOBAL, SHOOT, STATUS, GLOBAL 0, LED on): the run
    # must fail with an error naming the port and the last command, and a rerun must finish.
    with SimulatedRig(tmp_path / "incoming", 2, 2, W, H, faults=Faults(silent_from=38)) as sim:
        with pytest.raises(DeviceTimeout) as info:
            _run(sim, tmp_path)
        assert sim.url in str(info.value) and "SHOOT 10" in str(info.value)
        first = json.loads((tmp_path / "manifest.json").read_text())
        assert first["frames_in_place"] == 10 and not first["complete"]
        assert first["events"][-1]["event"] == "error"
        sim.device.revive()
        result = _run(sim, tmp_path)
        shots = len(sim.device.shots)
    assert result.complete and result.already == first["frames_in_place"]
    assert result.already + result.taken == 27
    assert shots == 27  # across both runs the shutter fired once per frame
    manifest = _check_session(tmp_path, sim)
    assert [e["event"] for e in manifest["events"]][:3] == ["start", "error", "resume"]


def test_a_crash_between_file_and_record_retakes_that_frame_once(tmp_path, monkeypatch):
    """The process dies after moving frame 5's image into place but before recording it."""
    real = Session._append
    calls = {"frames": 0}

    def dying(self, entry):
        if entry.get("type") == "frame":
            calls["frames"] += 1
            if calls["frames"] == 5:
                raise KeyboardInterrupt  # as if killed here
        real(self, entry)

    with SimulatedRig(tmp_path / "incoming", 2, 2, W, H) as sim:
        monkeypatch.setattr(Session, "_append", dying)
        with pytest.raises(KeyboardInterrupt):
            _run(sim, tmp_path)
        monkeypatch.setattr(Session, "_append", real)
        # The orphan file is there, unrecorded.
        assert (tmp_path / "frames" / "p000-b00l01-e1.exr").exists()
        result = _run(sim, tmp_path)
    assert result.complete and result.already == 4
    _check_session(tmp_path, sim)  # one file per frame: the orphan was replaced, not doubled


def test_a_torn_journal_line_is_dropped(tmp_path):
    with SimulatedRig(tmp_path / "incoming", 2, 2, W, H) as sim:
        _run(sim, tmp_path)
        journal = tmp_path / "frames.jsonl"
        lines = journal.read_text().splitlines(keepends=True)
        frame_lines = [k for k, l in enumerate(lines) if '"type":"frame"' in l]
        last = frame_lines[-1]
        # Cut the last frame's record in half, as a crash in mid-append would.
        journal.write_text("".join(lines[:last]) + lines[last][:40])
        result = _run(sim, tmp_path)
    assert result.taken == 1 and result.complete
    _check_session(tmp_path, sim)


def test_resume_with_another_plan_is_refused(tmp_path):
    with SimulatedRig(tmp_path / "incoming", 2, 2, W, H) as sim:
        _run(sim, tmp_path)
        other = plan_from_dict({**PLAN, "exposures_s": [0.01]})
        with pytest.raises(InputError, match="another plan"):
            _run(sim, tmp_path, other)


def test_plan_errors_name_the_field(tmp_path):
    path = tmp_path / "plan.json"
    path.write_text(json.dumps({**PLAN, "leds": [[0, 1], [0, "x"]]}))
    with pytest.raises(InputError, match=r"plan.json: leds\[1\]\[1\]"):
        read_plan(path)
    with pytest.raises(InputError, match="exposures_s"):
        plan_from_dict({"turntable": {"positions": 2}, "leds": [[0, 0]]})
    assert len(plan_from_dict({"turntable": {"angles_deg": [0, 90]}, "leds": [[1, 2]],
                               "exposures_s": [0.1, 0.2, 0.4]}).frames()) == 6


def test_cli_capture_simulated_and_resumed(tmp_path, capsys):
    from abs.cli.main import main

    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(PLAN))
    out = tmp_path / "session"
    args = ["rig", "capture", "--simulate", "--plan", str(plan), "--out", str(out), "--sim-size", "16x12"]
    assert main(args) == 0
    assert "27/27 frames (27 taken now" in capsys.readouterr().out
    assert main(args + ["--sim-link", "pty"]) == 0
    assert "27/27 frames (0 taken now, 27 before" in capsys.readouterr().out
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] and "not abs's renderer" in manifest["camera_model"]
    # A controller that stops answering: exit status 3, the port and command named; then resume.
    faulty = ["rig", "capture", "--simulate", "--plan", str(plan), "--out", str(tmp_path / "f"),
              "--sim-size", "16x12", "--timeout", "0.1", "--retries", "1"]
    assert main(faulty + ["--sim-fault", "silent@20", "--sim-fault", "garble@5",
                          "--sim-fault", "reset@12"]) == 3
    err = capsys.readouterr().err
    assert "socket://127.0.0.1:" in err and "stopped answering" in err and "run the same command" in err
    assert main(faulty) == 0
    assert "27/27 frames" in capsys.readouterr().out
    assert main(["rig", "capture", "--port", "socket://127.0.0.1:1", "--plan", str(plan), "--out",
                 str(tmp_path / "x"), "--camera-folder", str(tmp_path / "cf")]) == 3
    assert "socket://127.0.0.1:1" in capsys.readouterr().err


def test_sigkill_and_resume_from_the_command_line(tmp_path):
    """The real thing: ``abs rig capture --simulate`` killed with SIGKILL in mid-session (no
    ``finally`` runs), then the same command again."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from abs.cli.main import main
    from rig.sim import default_dome

    plan_data = {"turntable": {"positions": 4}, "global_light": {"level": 255, "exposures_s": [0.02]},
                 "leds": {"boards": 2, "leds_per_board": 3}, "exposures_s": [0.01, 0.04],
                 "settle_s": 0.05}  # 28 groups x 50 ms: time to kill it in the middle
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(plan_data))
    out = tmp_path / "session"
    args = ["rig", "capture", "--simulate", "--plan", str(plan), "--out", str(out), "--sim-size", "16x12"]
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "abs.cli.main", *args], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    journal = out / "frames.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if journal.exists() and journal.read_bytes().count(b'"type":"frame"') >= 8:
            break
        time.sleep(0.002)
    assert proc.poll() is None, f"finished before it could be killed: {proc.stderr.read()}"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    before = json.loads((out / "manifest.json").read_text())
    assert not before["complete"]
    assert main(args) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    expected = plan_from_dict(plan_data).frames()
    assert [f["id"] for f in manifest["frames"]] == [f.id for f in expected] and manifest["complete"]
    assert sorted(p.name for p in (out / "frames").iterdir()) == sorted(
        Path(f["file"]).name for f in manifest["frames"])
    resumed = [e for e in manifest["events"] if e["event"] == "resume"]
    assert len(resumed) == 1 and resumed[0]["frames_in_place"] >= 8
    dome = default_dome(2, 3)
    for spec, record in zip(expected, manifest["frames"]):
        light = spec.light
        leds = {(light.board, light.led): light.level} if light.kind == "led" else {}
        image = render_frame(dome, 16, 12, spec.angle_deg,
                             light.level if light.kind == "global" else 0, leds, spec.exposure_s)
        np.testing.assert_allclose(read_image(out / record["file"]), image, atol=1e-6)


def test_frames_rendered_by_abs(tmp_path):
    """``renderer="abs"``: the same session code, frames from abs's point-light pass (a Lambertian
    box); the turntable's quarter turn shows in the image, the LED lights the box."""
    plan = plan_from_dict({"turntable": {"angles_deg": [0, 90]}, "leds": [[0, 0]], "exposures_s": [0.01]})
    with SimulatedRig(tmp_path / "incoming", 1, 1, W, H, renderer="abs") as sim:
        result = _run(sim, tmp_path, plan)
    assert result.complete
    a, b = (read_image(tmp_path / "frames" / f"p00{k}-b00l00-e0.exr") for k in (0, 1))
    assert a.max() > 0.05 and b.max() > 0.05  # lit
    assert (a > 0).any(axis=2).sum() > 1.3 * (b > 0).any(axis=2).sum()  # broad side, then narrow
