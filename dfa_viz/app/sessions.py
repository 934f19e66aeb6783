"""Sessions on disk: an append-only JSON-lines log of every user action, plus the files it names.

A session folder holds:
    session.jsonl   one JSON object per line; the first is the header
                    {"type": "session", "version": 1, "world": ...}; then one event per user
                    action or finished job (dfa_viz.app.events: one class per type).
    demo-NNNN.npz   demonstrations (sim.core.Trajectory files) named by "demonstration" events.
    finetuned-NNNN.npz, policy-NNNN/   the finetuned rollout and checkpoint of a "finetune" event.
    session.lock    held (flock) while a server has the session open.

Every append is written, flushed and fsynced before `append` returns, so the page acknowledges
an action only once it is on disk. Reading never writes: a malformed file raises SessionError
naming the file and line and leaves the folder as it was. A line is written whole with its
newline (sim.core.files.append_bytes: a write that fails, a full disk, is cut back), so a last
line without its newline was cut short by a crash and never acknowledged, even where what is
there parses: it is reported in `notes`, dropped, and cut off before the next append.
"""

from __future__ import annotations

import fcntl
import json
import os
import threading
import time
from pathlib import Path
from typing import Any

from dfa_viz.app import events
from sim.core import Trajectory, UserError, files

LOG = "session.jsonl"
LOCK = "session.lock"
VERSION = events.VERSION
Entry = tuple[int, Any]  # (line number, typed event of dfa_viz.app.events)


class SessionError(UserError):
    """A session folder that cannot be read or opened; the message names the file and line."""


def _event(path: Path, line: int, raw: Any):
    """The typed event of one line, or a SessionError naming the file and line."""
    try:
        return events.from_json(raw)
    except UserError as e:
        raise SessionError(f"{path}:{line}: {e}") from None


def _why_not_json(e: BaseException) -> str:
    if isinstance(e, json.JSONDecodeError):
        return e.msg
    if isinstance(e, UnicodeDecodeError):
        return "not UTF-8 text"
    if isinstance(e, RecursionError):
        return "nested too deeply"
    if "digits" in str(e):  # int("9" * 5000): more digits than Python converts
        return "a number with too many digits"
    return str(e).splitlines()[0][:100] if str(e) else type(e).__name__


def read_events(folder: Path) -> tuple[list[Entry], int, list[str]]:
    """Parse and check session.jsonl without writing anything.

    Returns (entries, bytes of complete lines, notes): (line number, typed event) per line.
    """
    path = folder / LOG
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise SessionError(f"{path}: cannot read the session log ({e.strerror})") from None
    entries: list[Entry] = []
    notes: list[str] = []
    good_size = 0
    lines = raw.split(b"\n")
    for i, chunk in enumerate(lines, start=1):
        if i == len(lines):  # after the last newline
            if chunk:  # cut short by a crash: never acknowledged, whatever it holds
                notes.append(
                    f"{path}:{i}: incomplete last line (the server stopped while writing it); "
                    "it is ignored and will be cut off"
                )
            break
        try:
            text = chunk.decode("utf-8")
            event = json.loads(text)
        except (ValueError, RecursionError) as e:  # UnicodeDecodeError, JSONDecodeError, ...
            raise SessionError(f"{path}:{i}: not a JSON line ({_why_not_json(e)})") from None
        entries.append((i, _event(path, i, event)))
        good_size += len(chunk) + 1
    if not entries:
        raise SessionError(f"{path}:1: empty session log; expected a session header line")
    head = entries[0][1]
    if not isinstance(head, events.SessionStarted):
        raise SessionError(
            f"{path}:1: the first line must be the session header, not a {head.TYPE} event"
        )
    for line, e in entries[1:]:
        if isinstance(e, events.SessionStarted):
            raise SessionError(f"{path}:{line}: a second session header")
    return entries, good_size, notes


class Session:
    """One open session folder: a durable, thread-safe `append`, and the entries the log held
    when it was opened (`replay`, to rebuild the state from; handed out once and then
    dropped, so that no event stays in memory: they are on disk)."""

    def __init__(self, folder: Path, entries: list[Entry], size: int, notes: list[str]):
        self.folder = folder
        self.world = entries[0][1].world if entries else ""
        self.lines = len(entries)
        self._replay = entries[1:]
        self.notes = notes
        self._size = size  # bytes of complete lines; a torn tail beyond it is cut on append
        self._lock = threading.Lock()
        self._lock_fd: int | None = None

    @property
    def path(self) -> Path:
        return self.folder / LOG

    @classmethod
    def open(cls, folder: str | Path, *, world: str) -> Session:
        """Resume `folder` if it holds a session, else start one there (created if needed)."""
        folder = Path(folder)
        try:
            events.SessionStarted.from_json({"version": VERSION, "world": world})
        except UserError as e:
            raise SessionError(f"{folder}: {e}") from None
        if (folder / LOG).exists():
            entries, size, notes = read_events(folder)
            session = cls(folder, entries, size, notes)
        else:
            if folder.exists() and not folder.is_dir():
                raise SessionError(f"{folder}: not a folder")
            folder.mkdir(parents=True, exist_ok=True)
            session = cls(folder, [], 0, [])
            session._acquire()
            try:
                session.append(events.SessionStarted(world))
            except BaseException:
                session.close()
                raise
            session.world = world
            return session
        session._acquire()
        return session

    @classmethod
    def new(cls, root: str | Path, *, world: str) -> Session:
        """A fresh session under root/<date-time>/ (its tasks may be of any world: each
        recording's name says its own)."""
        stamp = time.strftime("%Y%m%d-%H%M%S")
        root = Path(root)
        for k in range(1000):
            folder = root / (stamp + (f"-{k}" if k else ""))
            if not folder.exists():
                return cls.open(folder, world=world)
        raise SessionError(f"{root}: could not find a free session folder name")

    def _acquire(self) -> None:
        fd = os.open(self.folder / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise SessionError(
                f"{self.folder}: the session is open in another running server; stop it first"
            ) from None
        self._lock_fd = fd

    def close(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None

    def replay(self) -> list[Entry]:
        """The (line, event) entries read at open, after the header (once; then [])."""
        entries, self._replay = self._replay, []
        return entries

    def append(self, event) -> int:
        """Write one event line; returns its line number once it is flushed and fsynced.
        A closed session (its server stopping, the folder released) takes nothing more."""
        if self._lock_fd is None:
            raise SessionError(f"{self.folder}: the session is closed; nothing more is written")
        doc = {"type": event.TYPE, **event.to_json(), "time": time.strftime("%Y-%m-%dT%H:%M:%S")}
        line = (json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n").encode()
        with self._lock:
            if not self.path.exists():  # the header: the log is there whole, or not at all
                files.write_bytes(self.path, line)
            else:
                if self.path.stat().st_size != self._size:
                    os.truncate(self.path, self._size)  # a torn tail left by a crash
                files.append_bytes(self.path, line)  # the whole line, fsynced, or nothing
            self._size += len(line)
            self.lines += 1
            return self.lines

    # -- files next to the log ----------------------------------------------------------------
    def next_name(self, stem: str, suffix: str = "") -> str:
        """A file name not used yet: <stem>-NNNN<suffix>, numbered by the log's length."""
        k = self.lines
        while (self.folder / f"{stem}-{k:04d}{suffix}").exists():
            k += 1
        return f"{stem}-{k:04d}{suffix}"

    def save_trajectory(self, traj: Trajectory, stem: str) -> str:
        """Write a trajectory durably next to the log (Trajectory.save fsyncs); returns its
        file name."""
        name = self.next_name(stem, ".npz")
        traj.save(self.folder / name)
        return name

    def file(self, name: str, line: int | str = "?") -> Path:
        """The path of a file an event names; it must be a plain name inside the folder."""
        if not name or "/" in name or "\\" in name or name in (".", ".."):
            raise SessionError(
                f"{self.path}:{line}: {name!r} is not a file name in the session folder"
            )
        return self.folder / name

    def load_trajectory(self, name: str, line: int | str = "?") -> Trajectory:
        try:
            return Trajectory.load(self.file(name, line))
        except UserError as e:
            if isinstance(e, SessionError):
                raise
            raise SessionError(f"{self.path}:{line}: the file it names is unusable: {e}") from None

    def load_policy(self, name: str, world, line: int | str = "?", *, base=None):
        """A checkpoint folder the session saved (policy.load_policy, checked for `world`);
        `base`: the policy the page diagnoses, whose finetuned copy an outside policy's is."""
        from policy import load_policy

        try:
            return load_policy(self.file(name, line), world=world, base=base)
        except UserError as e:
            if isinstance(e, SessionError):
                raise
            raise SessionError(
                f"{self.path}:{line}: the folder it names is unusable: {e}"
            ) from None
