"""The drop-folder camera (trigger, file arrival, strays) and the session folder's lock."""

from __future__ import annotations

import sys
import threading

import pytest

from abs.errors import InputError
from rig.camera import CommandTrigger, DropFolderCamera
from rig.errors import CameraError
from rig.plan import plan_from_dict
from rig.session import Session


def test_an_image_written_by_a_trigger_program_is_picked_up(tmp_path):
    folder = tmp_path / "tether"
    script = ("import pathlib, sys, time; p = pathlib.Path(sys.argv[1]); "
              "p.with_suffix('.part').write_bytes(b'x' * 100); "
              "p.with_suffix('.part').rename(p.with_name('IMG_' + sys.argv[2] + '.cr2'))")
    camera = DropFolderCamera(folder, CommandTrigger([sys.executable, "-c", script,
                                                      str(folder / "shot"), "{exposure_s}"]),
                              timeout_s=10.0)
    (folder / "old.cr2").write_bytes(b"left over")  # there before: never taken for a new image
    image = camera.capture(0.25)
    assert image.name == "IMG_0.25.cr2" and image.read_bytes() == b"x" * 100


def test_no_image_is_a_camera_error_naming_the_folder(tmp_path):
    camera = DropFolderCamera(tmp_path, lambda exposure_s: None, timeout_s=0.1)
    with pytest.raises(CameraError, match=str(tmp_path)):
        camera.capture(0.01)


def test_a_failing_trigger_program_is_a_camera_error(tmp_path):
    camera = DropFolderCamera(tmp_path, CommandTrigger([sys.executable, "-c", "raise SystemExit(4)"]))
    with pytest.raises(CameraError, match="exited 4"):
        camera.capture(0.01)


def test_a_late_image_is_a_stray_not_the_next_frame(tmp_path):
    def late(exposure_s: float) -> None:
        # The image of a failed exposure arrives 50 ms after the trigger gave up.
        threading.Timer(0.05, lambda: (tmp_path / "late.exr").write_bytes(b"x")).start()
        raise RuntimeError("controller restarted")

    camera = DropFolderCamera(tmp_path, late, timeout_s=1.0)
    with pytest.raises(RuntimeError):
        camera.capture(0.01)
    assert camera.strays(0.3) == [tmp_path / "late.exr"]
    assert camera.strays(0.0) == []


def test_one_session_folder_one_process(tmp_path):
    plan = plan_from_dict({"turntable": {"positions": 1}, "leds": [[0, 0]], "exposures_s": [0.1]})
    device = {"name": "x", "boards": 1, "leds_per_board": 1}
    first = Session.open(tmp_path, plan, device, "loop://", "camera")
    with pytest.raises(InputError, match="another process"):
        Session.open(tmp_path, plan, device, "loop://", "camera")
    first.close()
    Session.open(tmp_path, plan, device, "loop://", "camera").close()
    with pytest.raises(InputError, match="device.boards"):
        Session.open(tmp_path, plan, {**device, "boards": 2}, "loop://", "camera")
