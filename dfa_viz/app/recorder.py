"""The recording of the page's current task: one .rrd per task under out/, named like `dfa
run`'s plus the session and the line of the task in its log (loading another task, or this one
again, keeps this one), rewritten only when what it shows changed."""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from pathlib import Path

from dfa_viz.recording import write_recording
from dfa_viz.run_record import RunRecord
from sim.core import World, files

Snapshot = Callable[[], tuple[World | None, RunRecord | None, int, Path | None]]


class Recorder:
    """The current task's recording path and the content version it was last written at."""

    def __init__(self, out: Path) -> None:
        self.out = Path(out)
        self.path: Path | None = None
        self._written = -1
        self._lock = threading.Lock()

    def new_task(self, world: str, shift: str, seed: int, session: str, line: int) -> None:
        self.path = self.out / files.safe_name(
            f"{world}-{shift}-seed{seed}-session-{session}-task{line}.rrd"
        )
        self._written = -1

    def write(self, snapshot: Snapshot) -> Path | None:
        """(Re)write the .rrd of `snapshot()` (world, record, content version and path, taken
        under the caller's lock) when its version is not the one written; one at a time."""
        with self._lock:
            world, rec, version, path = snapshot()
            if world is None or rec is None or path is None:
                return None
            if self._written == version and path.exists():
                return path
            write_recording(path, world, dataclasses.replace(rec, recording=str(path)))
            self._written = version
            return path
