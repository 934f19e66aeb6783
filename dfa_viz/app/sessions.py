"""Sessions on disk: an append-only JSON-lines log of every user action, plus the files it names.

A session folder holds:
    session.jsonl   one JSON object per line; the first is the header
                    {"type": "session", "version": 1, "world": ...}; then one event per user
                    action or finished job (see EVENTS for each type's fields).
    demo-NNNN.npz   demonstrations (sim.core.Trajectory files) named by "demonstration" events.
    finetuned-NNNN.npz, policy-NNNN/   the finetuned rollout and checkpoint of a "finetune" event.
    session.lock    held (flock) while a server has the session open.

Every append is written, flushed and fsynced before `append` returns, so the page acknowledges
an action only once it is on disk. Reading never writes: a malformed file raises SessionError
naming the file and line and leaves the folder as it was. A last line cut short by a crash
(no newline, not valid JSON) was never acknowledged; it is reported in `notes`, dropped, and
cut off before the next append.
"""

from __future__ import annotations

import fcntl
import json
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sim import WORLDS
from sim.core import Trajectory, UserError, check_seed, check_shift

LOG = "session.jsonl"
LOCK = "session.lock"
VERSION = 1

# event type -> required fields and their JSON types (bool is checked apart from int)
EVENTS: dict[str, dict[str, tuple[type, ...]]] = {
    "session": {"version": (int,), "world": (str,)},
    "task": {"world": (str,), "shift": (str,), "seed": (int,), "task_seed": (int,)},
    "judgement": {"failed": (bool,)},
    "demonstration": {"file": (str,), "source": (str,)},
    "search": {
        "size": (int, type(None)),
        "max_size": (int,),
        "counterfactuals": (list,),
        "tried": (list,),
    },
    "tie": {"index": (int,)},
    "mark": {"slot": (str,), "concept": (str,), "label": (str,), "acceptable": (list,)},
    "finetune": {
        "feedback": (list,),
        "n_augmented": (int,),
        "losses": (list,),
        "success_before": (int, float),
        "success_after": (int, float),
        "rollout_file": (str,),
        "policy_dir": (str,),
    },
}


def _check_world(world: str, name: str = "") -> None:
    if world not in WORLDS:
        where = f"{name}: " if name else ""
        raise UserError(f"{where}unknown world {world!r}; accepted: {', '.join(WORLDS)}")


def _check_shift(shift: str, name: str) -> None:
    try:
        check_shift(shift)
    except UserError as e:
        raise UserError(f"{name}: {e}") from None


def _check_count(value: int, name: str) -> None:
    if value < 0:
        raise UserError(f"{name} must not be negative, got {value}")


# (event type, field) -> a check of its value beyond its JSON type: check(value, "type.field")
# raises UserError saying what is wrong and what is accepted
VALUES: dict[tuple[str, str], Callable[[Any, str], object]] = {
    ("session", "world"): _check_world,
    ("task", "world"): _check_world,
    ("task", "shift"): _check_shift,
    ("task", "seed"): check_seed,
    ("task", "task_seed"): check_seed,
    ("tie", "index"): _check_count,
    ("search", "max_size"): _check_count,
    ("finetune", "n_augmented"): _check_count,
}


class SessionError(UserError):
    """A session folder that cannot be read or opened; the message names the file and line."""


def _check_fields(path: Path, line: int, event: Any) -> None:
    where = f"{path}:{line}"
    if not isinstance(event, dict):
        raise SessionError(f"{where}: expected a JSON object, got {type(event).__name__}")
    kind = event.get("type")
    if not isinstance(kind, str) or kind not in EVENTS:
        shown = repr(kind) if isinstance(kind, str) else json.dumps(kind)[:60]
        raise SessionError(f"{where}: unknown event type {shown}; accepted: {', '.join(EVENTS)}")
    for key, types in EVENTS[kind].items():
        if key not in event:
            raise SessionError(
                f"{where}: {kind} event without {key!r}; it needs {', '.join(EVENTS[kind])}"
            )
        value = event[key]
        ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
        if not ok:
            names = " or ".join("null" if t is type(None) else t.__name__ for t in types)
            raise SessionError(
                f"{where}: {kind}.{key} must be {names}, got {json.dumps(value)[:60]}"
            )
    for key in EVENTS[kind]:  # the values, once every type is right
        check = VALUES.get((kind, key))
        if check is not None:
            try:
                check(event[key], f"{kind}.{key}")
            except UserError as e:
                raise SessionError(f"{where}: {e}") from None


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


def read_events(folder: Path) -> tuple[list[dict[str, Any]], int, list[str]]:
    """Parse and check session.jsonl without writing anything.

    Returns (events, bytes of complete lines, notes). Each event gets its line number under
    the key "_line".
    """
    path = folder / LOG
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise SessionError(f"{path}: cannot read the session log ({e.strerror})") from None
    events: list[dict[str, Any]] = []
    notes: list[str] = []
    good_size = 0
    lines = raw.split(b"\n")
    for i, chunk in enumerate(lines, start=1):
        last = i == len(lines)
        if last and not chunk:
            break  # the file ends with a newline, as it should
        try:
            text = chunk.decode("utf-8")
            event = json.loads(text)
        except (ValueError, RecursionError) as e:  # UnicodeDecodeError, JSONDecodeError, ...
            if last:  # cut short by a crash: never acknowledged
                notes.append(
                    f"{path}:{i}: incomplete last line (the server stopped while writing it); "
                    "it is ignored and will be cut off"
                )
                break
            raise SessionError(f"{path}:{i}: not a JSON line ({_why_not_json(e)})") from None
        _check_fields(path, i, event)
        event["_line"] = i
        events.append(event)
        good_size += len(chunk) + (0 if last else 1)
    if not events:
        raise SessionError(f"{path}:1: empty session log; expected a session header line")
    head = events[0]
    if head["type"] != "session":
        raise SessionError(
            f"{path}:1: the first line must be the session header, not a {head['type']} event"
        )
    if head["version"] != VERSION:
        raise SessionError(
            f"{path}:1: session format version {head['version']}; this program reads {VERSION}"
        )
    for e in events[1:]:
        if e["type"] == "session":
            raise SessionError(f"{path}:{e['_line']}: a second session header")
    return events, good_size, notes


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _summary(event: dict[str, Any]) -> dict[str, Any]:
    """An event without its list fields: what a session keeps in memory once the event is
    applied (a search's candidate lists would otherwise pile up, one per loop)."""
    return {k: v for k, v in event.items() if not isinstance(v, list)}


class Session:
    """One open session folder: its events so far and a durable, thread-safe `append`.

    `events` holds every event of the log in order, each with its "_line". Events read at
    open are whole until `forget_details()`; appended ones are kept as summaries (no list
    fields: those are on disk, and the caller of `append` gets the whole event).
    """

    def __init__(self, folder: Path, events: list[dict[str, Any]], size: int, notes: list[str]):
        self.folder = folder
        self.events = events
        self.notes = notes
        self._size = size  # bytes of complete lines; a torn tail beyond it is cut on append
        self._lock = threading.Lock()
        self._lock_fd: int | None = None

    @property
    def path(self) -> Path:
        return self.folder / LOG

    @property
    def world(self) -> str:
        return str(self.events[0]["world"])

    @classmethod
    def open(cls, folder: str | Path, *, world: str) -> Session:
        """Resume `folder` if it holds a session, else start one there (created if needed)."""
        folder = Path(folder)
        try:
            _check_world(world)
        except UserError as e:
            raise SessionError(f"{folder}: {e}") from None
        if (folder / LOG).exists():
            events, size, notes = read_events(folder)
            session = cls(folder, events, size, notes)
        else:
            if folder.exists() and not folder.is_dir():
                raise SessionError(f"{folder}: not a folder")
            folder.mkdir(parents=True, exist_ok=True)
            session = cls(folder, [], 0, [])
            session._acquire()
            session.append("session", version=VERSION, world=world)
            return session
        session._acquire()
        return session

    @classmethod
    def new(cls, root: str | Path, *, world: str) -> Session:
        """A fresh session under root/<date-time>-<world>/."""
        stamp = time.strftime("%Y%m%d-%H%M%S")
        root = Path(root)
        for k in range(1000):
            folder = root / (f"{stamp}-{world}" + (f"-{k}" if k else ""))
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

    def append(self, kind: str, **fields: Any) -> dict[str, Any]:
        """Write one event line; returns once it is flushed and fsynced."""
        event = {"type": kind, **fields, "time": time.strftime("%Y-%m-%dT%H:%M:%S")}
        _check_fields(self.path, len(self.events) + 1, event)
        line = (json.dumps(event, separators=(",", ":")) + "\n").encode()
        with self._lock:
            new = not self.path.exists()
            with open(self.path, "wb" if new else "r+b") as f:
                f.truncate(self._size)  # drop a torn tail left by a crash, if any
                if self._size:
                    f.seek(self._size - 1)
                    if f.read(1) != b"\n":  # a complete last line without its newline
                        line = b"\n" + line
                f.seek(self._size)
                f.write(line)
                f.flush()
                os.fsync(f.fileno())
            if new:
                _fsync_dir(self.folder)
            self._size += len(line)
            event["_line"] = len(self.events) + 1
            self.events.append(_summary(event))
        return event

    def forget_details(self) -> None:
        """Keep only the summary of each event so far (see `events`); once a session has been
        replayed its events' lists (every candidate a search tried, every loss) are needed
        on disk only."""
        with self._lock:
            self.events = [_summary(e) for e in self.events]

    # -- files next to the log ----------------------------------------------------------------
    def next_name(self, stem: str, suffix: str = "") -> str:
        """A file name not used yet: <stem>-NNNN<suffix>, numbered by the log's length."""
        k = len(self.events)
        while (self.folder / f"{stem}-{k:04d}{suffix}").exists():
            k += 1
        return f"{stem}-{k:04d}{suffix}"

    def save_trajectory(self, traj: Trajectory, stem: str) -> str:
        """Write a trajectory durably next to the log; returns its file name."""
        name = self.next_name(stem, ".npz")
        traj.save(self.folder / name)
        with open(self.folder / name, "rb") as f:
            os.fsync(f.fileno())
        _fsync_dir(self.folder)
        return name

    def file(self, name: str, event: dict[str, Any]) -> Path:
        """The path of a file an event names; it must be a plain name inside the folder."""
        if not name or "/" in name or "\\" in name or name in (".", ".."):
            raise SessionError(
                f"{self.path}:{event.get('_line', '?')}: {name!r} is not a file name in the "
                "session folder"
            )
        return self.folder / name

    def load_trajectory(self, name: str, event: dict[str, Any]) -> Trajectory:
        path = self.file(name, event)
        try:
            return Trajectory.load(path)
        except UserError as e:
            raise SessionError(
                f"{self.path}:{event.get('_line', '?')}: the file it names is unusable: {e}"
            ) from None
