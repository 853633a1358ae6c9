"""The camera: trigger an exposure, then wait for its image to arrive as a file in a folder.

Tethered cameras (gphoto2, vendor tethering software, a machine-vision SDK's save-to-folder) all
end in the same place: a new file in a folder. So the interface is that folder plus a trigger,
and the runner never needs to know the camera's make. Two triggers are provided: the rig
controller's ``SHOOT`` command (the camera's remote-release cable on a controller pin, exposure
in bulb mode) and an external program (``gphoto2 --set-config shutterspeed=... --trigger-capture``).
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

from rig.client import RigClient
from rig.errors import CameraError

__all__ = ["Camera", "DropFolderCamera", "SerialShutter", "CommandTrigger", "PARTIAL_SUFFIXES"]

PARTIAL_SUFFIXES = (".part", ".tmp", ".crdownload")
"""Names a camera program uses while it is still writing a file; never picked up."""


class Camera(Protocol):
    """What the capture runner needs from a camera."""

    def capture(self, exposure_s: float) -> Path:
        """Take one exposure of ``exposure_s`` seconds and return the new image file.

        Raises
        ------
        CameraError
            If no image arrives in time.
        """

    def strays(self, wait_s: float) -> list[Path]:
        """Images that arrived outside :meth:`capture` (late images of a failed exposure), after
        waiting up to ``wait_s`` seconds for them."""


class SerialShutter:
    """Trigger through the rig controller's ``SHOOT`` command (remote release, bulb mode).

    The controller acknowledges when the exposure has ended; a retried ``SHOOT`` is answered from
    the controller's memory, so a lost acknowledgement cannot fire the shutter twice.
    """

    def __init__(self, client: RigClient):
        self.client = client

    def __call__(self, exposure_s: float) -> None:
        self.client.shoot(exposure_s)


class CommandTrigger:
    """Trigger by running a program; ``{exposure_s}`` in its arguments becomes the exposure.

    Parameters
    ----------
    argv : sequence of str
        e.g. ``["gphoto2", "--set-config", "shutterspeed={exposure_s}", "--trigger-capture"]``.
    timeout_s : float
        Longest run of the program, seconds.
    """

    def __init__(self, argv: Sequence[str], timeout_s: float = 30.0):
        self.argv = list(argv)
        self.timeout_s = timeout_s

    def __call__(self, exposure_s: float) -> None:
        argv = [a.replace("{exposure_s}", f"{exposure_s:g}") for a in self.argv]
        try:
            done = subprocess.run(argv, capture_output=True, text=True, timeout=self.timeout_s)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise CameraError(f"camera trigger {argv!r} failed: {exc}") from exc
        if done.returncode != 0:
            raise CameraError(f"camera trigger {argv!r} exited {done.returncode}: "
                              f"{done.stderr.strip()[-300:]}")


class DropFolderCamera:
    """A camera whose images appear as new files in ``folder``.

    Parameters
    ----------
    folder : Path
        Where the camera (or its tethering program) saves images.
    trigger : callable
        ``trigger(exposure_s)`` starts one exposure.
    timeout_s : float
        Longest wait for the file after the trigger returned, seconds (download of a raw file
        over USB takes about a second).
    stable_s : float
        A file counts as complete once its size has not changed for this long, seconds; programs
        that write to a ``.part`` name and rename it are complete at once.
    suffixes : tuple of str, optional
        Only files with these suffixes (lower case, e.g. ``(".cr2",)`` when the camera saves raw
        and JPEG pairs) are images; default: any file.
    """

    def __init__(self, folder: Path, trigger: Callable[[float], None], timeout_s: float = 10.0,
                 stable_s: float = 0.0, suffixes: tuple[str, ...] | None = None, poll_s: float = 0.01):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.trigger = trigger
        self.timeout_s = timeout_s
        self.stable_s = stable_s
        self.suffixes = suffixes
        self.poll_s = poll_s
        self._known = set(self._images())  # files that are not images of ours

    def _images(self) -> dict[str, int]:
        out = {}
        for p in self.folder.iterdir():
            name = p.name.lower()
            if name.startswith(".") or name.endswith(PARTIAL_SUFFIXES) or not p.is_file():
                continue
            if self.suffixes is None or name.endswith(self.suffixes):
                out[p.name] = p.stat().st_size
        return out

    def capture(self, exposure_s: float) -> Path:
        # Files already there (leftovers of a crashed run, other programs' files) are not ours.
        before = set(self._images())
        self.trigger(exposure_s)
        deadline = time.monotonic() + self.timeout_s
        sizes: dict[str, tuple[int, float]] = {}
        new: dict[str, int] = {}
        while time.monotonic() < deadline:
            new = {n: s for n, s in self._images().items() if n not in before}
            if len(new) > 1:
                raise CameraError(f"{self.folder}: one trigger produced {len(new)} files "
                                  f"{sorted(new)}; set the camera to save one file per shot or "
                                  "restrict the suffixes")
            for name, size in new.items():
                seen = sizes.get(name)
                now = time.monotonic()
                if seen is None or seen[0] != size:
                    sizes[name] = (size, now)
                if size > 0 and now - sizes[name][1] >= self.stable_s:
                    self._known = before | {name}
                    return self.folder / name
            time.sleep(self.poll_s)
        self._known = before | set(new)
        raise CameraError(f"{self.folder}: no image arrived within {self.timeout_s:g} s of a "
                          f"{exposure_s:g} s exposure; is the camera on and saving to this folder?")

    def strays(self, wait_s: float = 1.0) -> list[Path]:
        """Images that arrived since the last :meth:`capture` returned, after waiting ``wait_s``
        seconds for late ones.

        After a failed exposure (the controller restarted during ``SHOOT``) the camera may still
        deliver that image; were it left in the folder, it could arrive during the next capture and
        be taken for that frame. The runner calls this after such a failure and moves the strays
        out of the way.
        """
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            time.sleep(self.poll_s)
        found = sorted(set(self._images()) - self._known)
        self._known |= set(found)
        return [self.folder / n for n in found]
