"""The session folder: frames, a journal of the frames that are in place, and ``manifest.json``.

Layout::

    SESSION/
      manifest.json    the plan, the device, every frame's record, the events (rewritten atomically)
      frames.jsonl     the journal: one line per frame in place (and per event), fsynced
      frames/          p000-global-e0.exr, p000-b00l00-e0.exr, ... (the camera's file type)
      discarded/       images taken but not proven (rig/runner.py)
      incoming/        the simulated camera's drop folder (real cameras use their own)

Why a journal beside the manifest: a frame must be recorded the moment its file is in place, and
rewriting a manifest of thousands of frames after each one costs O(n^2) bytes over a session
(40 positions x (one global frame + 36 LEDs x a 3-exposure bracket) is 4360 frames). Appending
one fsynced line is O(1). A crash can tear only the last line; :meth:`Session.open` drops a torn
line, so a frame is either recorded whole or not at all. ``manifest.json`` is written when a
session opens, rebuilt from the journal at the end of every turntable position and whenever the
runner stops, and then describes every recorded frame.

Order of writing one frame (why none is lost or taken twice): (1) the image is moved into
``frames/`` under its frame id (``os.replace``, atomic); (2) the record is appended to the
journal and fsynced. A crash before (2) leaves a file without a record: the frame is taken again on
resume and its file replaced, under the same name, so it is never there twice.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from abs.errors import InputError, read_json
from rig.plan import CapturePlan, FrameSpec

__all__ = ["Session", "MANIFEST_FORMAT"]

MANIFEST_FORMAT = "abs-rig-session/1"

try:  # POSIX: an advisory lock that the kernel releases when the process dies.
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (POSIX; a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON through a temporary file and ``os.replace``: readers see the old or the new
    file, never half of one."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


class Session:
    """An open session folder (use :meth:`open`).

    Attributes
    ----------
    folder : Path
        The session folder.
    records : dict of str to dict
        Every frame in place, by frame id.
    events : list of dict
        Starts, resumes, device restarts, errors, in order.
    """

    def __init__(self, folder: Path, plan: CapturePlan, header: dict[str, Any]):
        self.folder = folder
        self.frames_dir = folder / "frames"
        self.journal_path = folder / "frames.jsonl"
        self.manifest_path = folder / "manifest.json"
        self.plan = plan
        self.header = header
        self.records: dict[str, dict[str, Any]] = {}
        self.events: list[dict[str, Any]] = []
        self._lock_file = None
        self._journal = None

    # -- opening ----------------------------------------------------------------------------

    @classmethod
    def open(cls, folder: str | Path, plan: CapturePlan, device: dict[str, Any], port: str,
             camera_model: str) -> Session:
        """Create a session folder, or reopen one to resume it.

        Parameters
        ----------
        folder : str or Path
            The session folder (created if missing).
        plan : CapturePlan
            The plan; a resumed session must have been started with the same one.
        device : dict
            The controller's identity (``ID``'s name, firmware, layout).
        port : str
            The port it was reached on.
        camera_model : str
            What produced the images (``"camera"`` for real hardware; the simulated camera
            describes its model).

        Raises
        ------
        InputError
            If the folder holds a session of another plan or another device, a manifest that is
            not a rig session, or a journal line that is damaged other than at its end; or if
            another process has the session open.
        """
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        manifest_path = folder / "manifest.json"
        header = {"format": MANIFEST_FORMAT, "created_utc": _now(), "plan": plan.to_dict(),
                  "device": device, "camera_model": camera_model}
        if manifest_path.exists():
            old = read_json(manifest_path, what="session manifest")
            if old.get("format") != MANIFEST_FORMAT:
                raise InputError(manifest_path, "format", f"expected {MANIFEST_FORMAT!r}, got "
                                 f"{old.get('format')!r}: not a rig session folder")
            if old.get("plan") != plan.to_dict():
                raise InputError(manifest_path, "plan", "this session was started with another plan; "
                                 "resume it with the same plan file or use a new --out folder")
            for key in ("name", "boards", "leds_per_board"):
                if old.get("device", {}).get(key) != device.get(key):
                    raise InputError(manifest_path, f"device.{key}", f"session was taken on "
                                     f"{old['device'].get(key)!r}, this device reports "
                                     f"{device.get(key)!r}")
            header = {**header, "created_utc": old.get("created_utc", header["created_utc"])}
        session = cls(folder, plan, header)
        session._take_lock()
        session.frames_dir.mkdir(exist_ok=True)
        session._replay_journal()
        session._journal = open(session.journal_path, "a", encoding="utf-8")
        session.event("resume" if session.records or manifest_path.exists() else "start",
                      port=port, frames_in_place=len(session.records))
        # At once, so that even a run killed before its first position is done leaves the plan
        # behind for the next run to check against.
        session.write_manifest(complete=False)
        return session

    def _take_lock(self) -> None:
        if fcntl is None:
            return
        self._lock_file = open(self.folder / ".lock", "w")
        try:
            fcntl.flock(self._lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock_file.close()
            raise InputError(self.folder, "", "another process is capturing into this session "
                             "folder") from None
        self._lock_file.write(str(os.getpid()))
        self._lock_file.flush()

    def _replay_journal(self) -> None:
        """Read the journal; drop a torn last line (a crash in mid-append) and truncate it away."""
        if not self.journal_path.exists():
            return
        data = self.journal_path.read_bytes()
        # Whatever follows the last newline was never written whole: a torn append.
        *lines, _tail = data.split(b"\n")
        good_end = 0
        for k, raw in enumerate(lines):
            try:
                entry = json.loads(raw) if raw.strip() else None
            except json.JSONDecodeError:
                if k == len(lines) - 1:
                    break  # a damaged last line: the same torn append
                raise InputError(self.journal_path, f"line {k + 1}", "damaged journal line in the "
                                 "middle of the file; it was not written by an interrupted run") from None
            good_end += len(raw) + 1
            if entry is None:
                continue
            if entry.get("type") == "frame":
                if (self.folder / entry["file"]).is_file():
                    self.records[entry["id"]] = entry
                else:  # deleted by hand since: take it again
                    self.events.append({"type": "event", "event": "missing-file",
                                        "id": entry["id"], "utc": _now()})
            else:
                self.events.append(entry)
        if good_end < len(data):
            with open(self.journal_path, "r+b") as f:
                f.truncate(good_end)

    # -- writing -------------------------------------------------------------------------------

    def _append(self, entry: dict[str, Any]) -> None:
        assert self._journal is not None
        self._journal.write(json.dumps(entry, separators=(",", ":")) + "\n")
        self._journal.flush()
        os.fsync(self._journal.fileno())

    def event(self, event: str, **fields: Any) -> None:
        """Record an event (start, resume, reset, error) in the journal."""
        entry = {"type": "event", "event": event, "utc": _now(), **fields}
        self.events.append(entry)
        self._append(entry)

    def done(self, frame_id: str) -> bool:
        """Whether the frame's file is in place and recorded."""
        return frame_id in self.records

    def commit(self, spec: FrameSpec, image: Path, boot: str | None) -> dict[str, Any]:
        """Move an image into place as frame ``spec`` and record it.

        Parameters
        ----------
        spec : FrameSpec
            The frame the image is.
        image : Path
            The camera's file; it is moved (renamed where possible).
        boot : str or None
            The device's boot id throughout the exposure.

        Returns
        -------
        dict
            The frame's record, as in the manifest.
        """
        suffix = "".join(image.suffixes[-1:]).lower()
        target = self.frames_dir / f"{spec.id}{suffix}"
        # A file of this frame without a record is an orphan of a crash between move and record.
        for old in self.frames_dir.glob(f"{spec.id}.*"):
            if old != target:
                old.unlink()
        try:
            os.replace(image, target)
        except OSError as exc:
            if exc.errno != errno.EXDEV:
                raise
            # Another file system (camera folder on a network share): copy, sync, rename.
            tmp = self.frames_dir / f".{spec.id}{suffix}.tmp"
            shutil.copyfile(image, tmp)
            with open(tmp, "rb") as f:
                os.fsync(f.fileno())
            os.replace(tmp, target)
            image.unlink()
        _fsync_dir(self.frames_dir)
        light = spec.light
        record = {"type": "frame", "id": spec.id, "file": f"frames/{target.name}",
                  "position": spec.position, "angle_deg": spec.angle_deg, "light": light.name,
                  "light_kind": light.kind, "board": light.board if light.kind == "led" else None,
                  "led": light.led if light.kind == "led" else None, "level": light.level,
                  "exposure_index": spec.exposure_index, "exposure_s": spec.exposure_s,
                  "bytes": target.stat().st_size, "device_boot": boot, "utc": _now()}
        self._append(record)
        self.records[spec.id] = record
        return record

    def write_manifest(self, complete: bool) -> None:
        """Rewrite ``manifest.json`` from the records (atomically)."""
        order = [f.id for f in self.plan.frames()]
        frames = [self.records[i] for i in order if i in self.records]
        write_json_atomic(self.manifest_path, {
            **self.header, "updated_utc": _now(), "complete": complete,
            "frames_planned": len(order), "frames_in_place": len(frames),
            "frames": [{k: v for k, v in r.items() if k != "type"} for r in frames],
            "events": [{k: v for k, v in e.items() if k != "type"} for e in self.events]})

    def close(self) -> None:
        """Close the journal and release the lock."""
        if self._journal is not None:
            self._journal.close()
            self._journal = None
        if self._lock_file is not None:
            self._lock_file.close()
            self._lock_file = None
