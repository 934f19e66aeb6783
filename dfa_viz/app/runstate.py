"""The run of one page session so far: its record, the session log that keeps it, and its
recording.

The record is one RunRecord. Each step of the loop is one typed event (dfa_viz.app.events):
applied to a copy of the record first (one that would not apply is refused, unwritten, so every
line of the log replays), appended to the session log (flushed and fsynced), then taken, and
the tabs told (dfa_viz.app.hub). Replaying the log (dfa_viz.app.replay) rebuilds the same
record, so a restart with the same session resumes where it stopped. Once closed, nothing more
is written. Every read and write holds `self._lock`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from dfa_viz.app import events as E
from dfa_viz.app import replay as R
from dfa_viz.app.demonstrate import DemoInput, input_for
from dfa_viz.app.episodes import DemoEpisodes
from dfa_viz.app.hub import Hub
from dfa_viz.app.jobs import Cancelled, Jobs
from dfa_viz.app.offers import Offers
from dfa_viz.app.policies import Policies
from dfa_viz.app.recorder import Recorder
from dfa_viz.app.sessions import Session, SessionError
from dfa_viz.loop import AdaptConfig
from dfa_viz.run_record import RunRecord
from sim import get_world
from sim.core import UserError, World

STOP_WAIT_S = 10.0  # how long closing waits for a cancelled job to reach its next check


class RunState(Hub):
    """The run of one page session so far; see the module docstring. Subclasses resume a job
    the log shows cut off (`resume`)."""

    def __init__(
        self,
        session: Session,
        *,
        out: Path = Path("recordings"),
        adapt_config: AdaptConfig = AdaptConfig(),
        policies: Policies | None = None,
        demos: DemoEpisodes | None = None,
    ) -> None:
        super().__init__()
        self.session = session
        self.demos = demos
        """The dataset whose episodes the page offers as demonstrations (`dfa serve --demos`)."""
        self.adapt = adapt_config.check()
        self.policies = policies or Policies()
        self.offers = Offers.for_session(session.world)
        self.world_name = session.world
        self.world: World | None = None  # the loaded task's, resolved once per task
        self.record: RunRecord | None = None
        self.demo_input: DemoInput | None = None
        self.losses: list[float] = []  # live, while finetuning
        self.content = 0  # bumps on every committed event (what the recording shows)
        self.recorder = Recorder(out)
        self._closed = False
        self._finetuned_with: tuple | None = None  # (feedback, config) of the last finetuning
        self.sweep = None  # the Sweep tab's last sweep (dfa_viz.sweep.run.PageSweep), unlogged
        self.jobs = Jobs(self._notify)
        self._rebuild = R.Rebuild(
            policy=self.policies.get,
            trajectory=session.load_trajectory,
            checkpoint=lambda name, world: session.load_policy(
                name, world, base=self.policies.get(world)
            ),
        )
        self._replay()

    @property
    def worlds(self) -> tuple[str, ...]:
        return self.offers.worlds

    @property
    def out(self) -> Path:
        return self.recorder.out

    @property
    def recording(self) -> Path | None:
        return self.recorder.path

    @property
    def busy(self) -> bool:
        return self.jobs.current is not None

    def finetuned(self) -> bool:
        """Whether the task was finetuned with the marks it has now (and these settings)."""
        with self._lock:
            rec = self.record
            done = rec is not None and rec.adaptation is not None
            return done and self._finetuned_with == (rec.feedback, self.adapt)

    def close(self) -> None:
        """Stop: cancel the running job (it ends at its next check, or is abandoned after
        STOP_WAIT_S; either way its event is never written, so a restart redoes or offers the
        step again), stop taking input, and release the session folder. Nothing is written
        after this returns."""
        self.jobs.cancel()
        self.jobs.idle(STOP_WAIT_S)
        with self._lock:
            self._closed = True
        self.stop_inputs()
        self.session.close()

    # -- events: written, then taken (live), or replayed --------------------------------------
    def _take(self, event, record: RunRecord, line: int) -> None:
        """Take the record an event gave (holding the lock); a task event also resolves the
        world and names the recording; judged failed, a fresh demonstration input."""
        self.record = record
        if isinstance(event, E.Finetuned):
            self._finetuned_with = (event.feedback, event.config)
        if isinstance(event, E.TaskLoaded):
            self.world_name, self.world = event.world, get_world(event.world)
            self.demo_input = None
            folder = self.session.folder.name
            self.recorder.new_task(event.world, event.shift, event.seed, folder, line)
        elif isinstance(event, E.Judged) and event.failed and self.world is not None:
            self.demo_input = input_for(self.world, record.task)

    def _replay(self) -> None:
        for line, event in self.session.replay():
            try:
                with self._lock:
                    self._take(event, R.apply(self.record, event, self._rebuild), line)
            except UserError as e:
                if isinstance(e, SessionError):
                    raise
                raise SessionError(f"{self.session.path}:{line}: {e}") from None
        self.resume()

    def resume(self) -> None:
        """Start again a job the replayed log shows cut off; nothing by default."""

    def _commit(self, event, computed=None, notify: str = "stage") -> None:
        """Apply the event to a copy (an event that does not apply is refused, unwritten),
        append it durably, take the new record, then tell the tabs; nothing once closed."""
        with self._lock:
            if self._closed:
                raise Cancelled()
            record = R.apply(self.record, event, self._rebuild, computed)
            line = self.session.append(event)
            self._take(event, record, line)
            self.content += 1
        self._notify({notify})

    def _start(self, name: str, job: Callable[[], None], text: str) -> bool:
        """Start a job (False if one runs). Callers check that it may start and start it under
        the state lock: of two tabs pressing the same button at once, one starts the job and
        the other is refused or told why not."""
        with self._lock:
            if self._closed:
                raise Cancelled()
            return self.jobs.start(name, job, text)

    # -- recording ----------------------------------------------------------------------------
    def write_recording(self) -> Path | None:
        """(Re)write the task's .rrd under out/ when the state changed since the last write."""

        def snapshot():
            with self._lock:
                return self.world, self.record, self.content, self.recorder.path

        return self.recorder.write(snapshot)
