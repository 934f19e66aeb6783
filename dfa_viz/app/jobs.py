"""The page's long jobs (finding a task, the search, finetuning): one at a time, on a worker
thread, with progress the tabs can show. No loop logic here: a job is any function.

When the server stops, `cancel()` ends the running job at its next progress report (or
`check()`), quietly: its event was never written, so a restart offers the step again."""

from __future__ import annotations

import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass

from sim.core import UserError

Notify = Callable[[set[str]], None]


class Cancelled(UserError):
    """Raised inside a job that was cancelled, or by an action after the state was closed (the
    server is stopping); a job ends quietly on it."""

    def __init__(self) -> None:
        super().__init__("the server is stopping")


@dataclass(frozen=True)
class Job:
    """The job running now: its name, how far it got (0..1) and what it is doing."""

    name: str
    progress: float
    text: str


class Jobs:
    """Runs one job at a time; a second start while one runs is refused, harmlessly.

    `notify(what)` is called (outside any lock) when the job starts, reports progress, and
    ends ({"job"}, plus {"stage", "error"} at the end); an error a job raises is kept in
    `error` for the page to show (a UserError as its message, anything else with its type).
    """

    def __init__(self, notify: Notify) -> None:
        self._notify = notify
        self._lock = threading.Lock()
        self._job: Job | None = None
        self._error = ""
        self._idle = threading.Event()
        self._idle.set()
        self._cancelled = threading.Event()

    @property
    def current(self) -> Job | None:
        with self._lock:
            return self._job

    @property
    def error(self) -> str:
        with self._lock:
            return self._error

    def start(self, name: str, fn: Callable[[], None], text: str = "") -> bool:
        """Run `fn` on a new thread unless a job runs (or the runner was cancelled); False when
        refused. The tabs are notified from that thread, so a caller may hold its own lock."""
        with self._lock:
            if self._job is not None or self._cancelled.is_set():
                return False
            self._job = Job(name, 0.0, text or f"{name}…")
            self._error = ""
            self._idle.clear()
        threading.Thread(target=self._run, args=(fn,), name=f"dfa-{name}", daemon=True).start()
        return True

    def cancel(self) -> None:
        """End the running job at its next check and refuse new ones (the server stops)."""
        self._cancelled.set()

    @property
    def cancelled(self) -> bool:
        return self._cancelled.is_set()

    def check(self) -> None:
        """Raise Cancelled inside a job once the runner is cancelled."""
        if self._cancelled.is_set():
            raise Cancelled()

    def _run(self, fn: Callable[[], None]) -> None:
        error = ""
        try:
            self._notify({"job"})
            fn()
        except Cancelled:
            pass  # the server is stopping: nothing to show
        except UserError as e:
            error = str(e)
        except Exception as e:  # shown on the page; the server keeps running
            traceback.print_exc()
            error = f"{type(e).__name__}: {e}"
        finally:
            with self._lock:
                self._job, self._error = None, error
            self._notify({"job", "stage", "error"})
            with self._lock:  # idle once the tabs were told (a server stopping waits for it)
                if self._job is None:  # and no other job started meanwhile
                    self._idle.set()

    def progress(self, fraction: float, text: str) -> None:
        """Report the running job's progress (ignored when none runs); raises Cancelled in a
        cancelled job."""
        self.check()
        with self._lock:
            if self._job is None:
                return
            self._job = Job(self._job.name, max(0.0, min(1.0, fraction)), text)
        self._notify({"job"})

    def idle(self, timeout_s: float) -> bool:
        """Block until no job runs, at most timeout_s; whether none runs."""
        return self._idle.wait(timeout_s)

    def wait(self, timeout_s: float = 600.0) -> None:
        """Block until no job runs; raise the job's error as a UserError, if it left one."""
        if not self._idle.wait(timeout_s):
            job = self.current
            raise TimeoutError(f"a {job.name if job else ''} job took over {timeout_s} s")
        if self.error:
            raise UserError(self.error)
