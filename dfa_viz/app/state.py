"""The page's loop state, shared by every tab of one session.

Algorithm 1 driven by the user, as the loop's own steps (dfa_viz.loop):
    pick -> judge -> demonstrate -> diagnose (search job) -> feedback -> adapt (finetune job)
(`solved` when the user says the rollout succeeded). The run so far is one RunRecord. Each user
action is a typed event (dfa_viz.app.events), appended to the session log (flushed and
fsynced) before it is applied; applying an event returns the next record, and replaying the log
rebuilds the same record, so a restart with the same session resumes where it stopped.

Thread-safety: every read and write of the state holds `self._lock`; long jobs run one at a
time (dfa_viz.app.jobs), each started under the lock that checked it may start (two tabs
pressing the same button start one job); subscribers (the tabs) are called outside the lock
with the set of things that changed. An event that would not apply is refused before it is
written, so every line of the log replays. Once closed, nothing more is written.

The values of an action (a world, shift, seed, tie, mark, number of sweep tasks, dataset
episode) are checked here against what the page offers, whoever calls: a tab can send any value.
"""

from __future__ import annotations

import dataclasses
import itertools
import queue
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from dfa_viz.app import events as E
from dfa_viz.app.demonstrate import DemoInput, input_for
from dfa_viz.app.episodes import DemoEpisodes, chosen
from dfa_viz.app.jobs import Cancelled, Jobs
from dfa_viz.app.sessions import Session, SessionError
from dfa_viz.app.view import View
from dfa_viz.loop import AdaptConfig, RunRecord, adapt, diagnose, evaluate, start
from dfa_viz.recording import write_recording
from policy import Policy, base_policy, failing_test_task, save_policy, training_demos
from policy.outside import chosen_policy
from search import SearchConfig
from sim import get_world, world_names
from sim.core import (
    Label,
    UserError,
    World,
    check_seed,
    files,
    require_success,
)

Listener = Callable[[set[str]], None]
LOSS_NOTIFY_S = 0.2  # at most this often while finetuning
SWEEP_TASKS = (1, 500)  # the Sweep tab's range of training tasks
STOP_WAIT_S = 10.0  # how long closing waits for a cancelled job to reach its next check


class Policies:
    """The policy diagnosed in each world (its base policy, or the one `dfa serve --policy`
    names for the world the page opens on) and the training demonstrations, made once per
    process."""

    def __init__(
        self, *, spec: str | None = None, world: str | None = None, weights: Path | None = None
    ) -> None:
        self._lock = threading.Lock()
        self._policies: dict[str, Policy] = {}
        self._known: dict[str, tuple] = {}
        self._spec, self._spec_world, self._weights = spec, world, weights

    def get(self, world: World) -> Policy:
        with self._lock:
            if world.name not in self._policies:
                if world.name == self._spec_world:
                    policy = chosen_policy(world, self._spec, self._weights)
                else:
                    policy = base_policy(world)
                policy.fits(world)
                self._policies[world.name] = policy
            return self._policies[world.name]

    def known(self, world: World) -> tuple:
        """The base policy's training demonstrations (variant sources, replayed), where the
        world has a training distribution."""
        with self._lock:
            if world.name not in self._known:
                self._known[world.name] = tuple(training_demos(world)) if world.benchmark else ()
            return self._known[world.name]


class LoopState:
    """One session's loop, driven by the page; see the module docstring."""

    def __init__(
        self,
        session: Session,
        *,
        out: Path = Path("recordings"),
        adapt_config: AdaptConfig = AdaptConfig(),
        policies: Policies | None = None,
        demos: DemoEpisodes | None = None,
    ) -> None:
        self.session = session
        self.demos = demos
        """The dataset whose episodes the page offers as demonstrations (`dfa serve --demos`)."""
        self.out = Path(out)
        self.adapt = adapt_config.check()
        self.policies = policies or Policies()
        self.world_name = session.world
        worlds = tuple(n for n in world_names() if not n.endswith(":..."))
        self.worlds = worlds if session.world in worlds else (*worlds, session.world)
        """The worlds the page offers: the registered ones and the session's own."""
        self.record: RunRecord | None = None
        self.demo_input: DemoInput | None = None
        self.losses: list[float] = []  # live, while finetuning
        self.version = 0  # bumps on every notification
        self.content = 0  # bumps on every committed event (what the recording shows)
        self.recording: Path | None = None
        self._recorded = -1
        self._closed = False
        self._finetuned_with: tuple | None = None  # (feedback, config) of the last finetuning
        self.sweep = None  # the Sweep tab's last sweep (dfa_viz.sweep.run.PageSweep), unlogged
        self._lock = threading.RLock()
        self._record_lock = threading.Lock()
        self._listeners: dict[int, Listener] = {}
        self._ids = itertools.count()
        self.jobs = Jobs(self._notify)
        self._rebuild = E.Rebuild(
            policy=self.policies.get,
            trajectory=lambda name: session.load_trajectory(name),
            checkpoint=lambda name, world: session.load_policy(
                name, world, base=self.policies.get(world)
            ),
        )
        self._inputs: queue.Queue = queue.Queue()
        threading.Thread(target=self._input_loop, name="dfa-inputs", daemon=True).start()
        self._replay()

    # -- ordered input: clicks and keys apply in the order they arrived -----------------------
    def submit(self, fn: Callable[[], object], on_error: Callable[[str], None]) -> None:
        """Queue a quick user input (a waypoint, a key); the page calls this from viser's event
        loop, where messages arrive in order (thread-pool callbacks could overtake each other)."""
        self._inputs.put((fn, on_error))

    def _input_loop(self) -> None:
        while True:
            item = self._inputs.get()
            if item is None:  # closed
                return
            fn, on_error = item
            try:
                fn()
            except UserError as e:
                on_error(str(e))
            except Exception as e:
                traceback.print_exc()
                on_error(f"{type(e).__name__}: {e}")

    def close(self) -> None:
        """Stop: cancel the running job (it ends at its next check, or is abandoned after
        STOP_WAIT_S; either way its event is never written, so a restart redoes or offers the
        step again), stop taking input, and release the session folder. Nothing is written
        after this returns."""
        self.jobs.cancel()
        self.jobs.idle(STOP_WAIT_S)
        with self._lock:
            self._closed = True
        self._inputs.put(None)
        self.session.close()

    # -- subscribers --------------------------------------------------------------------------
    def subscribe(self, fn: Listener) -> Callable[[], None]:
        key = next(self._ids)
        with self._lock:
            self._listeners[key] = fn

        def unsubscribe() -> None:
            with self._lock:
                self._listeners.pop(key, None)

        return unsubscribe

    def _notify(self, what: set[str]) -> None:
        with self._lock:
            self.version += 1
            listeners = list(self._listeners.values())
        for fn in listeners:
            try:
                fn(what)
            except Exception:  # one broken tab must not stop the others
                traceback.print_exc()

    # -- events: written, then applied (live), or replayed ------------------------------------
    def _take(self, event, record: RunRecord, line: int) -> None:
        """Take the record an event gave (holding the lock); the task event also names the
        recording and makes a fresh demonstration input when judged failed."""
        self.record = record
        if isinstance(event, E.Finetuned):
            self._finetuned_with = (event.feedback, event.config)
        if isinstance(event, E.TaskLoaded):
            self.world_name = event.world
            self.demo_input = None
            # like `dfa run`'s <world>-<shift>-seed<seed>.rrd, plus the session and the line of
            # this task in its log: loading another task (or this one again) keeps this one
            self.recording = self.out / files.safe_name(
                f"{event.world}-{event.shift}-seed{event.seed}-session-"
                f"{self.session.folder.name}-task{line}.rrd"
            )
            self._recorded = -1
        elif isinstance(event, E.Judged) and event.failed:
            self.demo_input = input_for(get_world(self.record.world), self.record.task)

    def _replay(self) -> None:
        for line, event in self.session.replay():
            try:
                with self._lock:
                    self._take(event, E.apply(self.record, event, self._rebuild), line)
            except UserError as e:
                if isinstance(e, SessionError):
                    raise
                raise SessionError(f"{self.session.path}:{line}: {e}") from None
        if self.record is not None and self.record.stage == "diagnose":
            self.jobs.start("search", self._search_job)  # the search was cut off: run it again

    def _commit(self, event, computed=None) -> None:
        """Apply the event to a copy (an event that does not apply is refused, unwritten),
        append it durably, then take the new record; all under the state lock, and nothing
        once the state is closed."""
        with self._lock:
            if self._closed:
                raise Cancelled()
            record = E.apply(self.record, event, self._rebuild, computed)
            line = self.session.append(event)
            self._take(event, record, line)
            self.content += 1

    def _start(self, name: str, job: Callable[[], None], text: str) -> bool:
        """Start a job (False if one runs). Callers check that it may start and start it under
        the state lock: of two tabs pressing the same button at once, one starts the job and
        the other is refused or told why not."""
        with self._lock:
            if self._closed:
                raise Cancelled()
            return self.jobs.start(name, job, text)

    # -- what the tabs draw -------------------------------------------------------------------
    def snapshot(self) -> View:
        with self._lock:
            rec, d = self.record, self.demo_input
            return View(
                self.version,
                self.world_name,
                None if rec is None else get_world(rec.world),
                rec,
                "pick" if rec is None else rec.stage,
                self.jobs.current,
                self.jobs.error,
                tuple(self.losses),
                d.kind if d else "",
                d.hint if d else "",
                d.summary() if d else "",
                d.given() if d else False,
                d.ready() if d else False,
                d.problem() if d else "",
                self.recording,
                self.session.folder,
                self.adapt,
                self.finetuned(),
            )

    def demo_canvas(self):
        """uint8 (H, W, 3): the demonstration canvas, or the task's first frame; None before
        a task is picked."""
        with self._lock:
            rec = self.record
            if self.demo_input is not None and rec is not None and rec.stage == "demonstrate":
                return self.demo_input.canvas()
            if rec is None:
                return None
            from dfa_viz.app import frames

            k = frames.scale_for(rec.rollout.observations.shape[1:], frames.CANVAS_PX)
            return frames.upscale(rec.rollout.observations[0], k)

    def demo_keys(self):
        with self._lock:
            return self.demo_input.keys if self.demo_input is not None else ()

    @property
    def busy(self) -> bool:
        return self.jobs.current is not None

    # -- user actions -------------------------------------------------------------------------
    def offered(self, world: str) -> World:
        """The world, if the page offers it; else a UserError (nothing is built for it)."""
        if world not in self.worlds:
            raise UserError(f"no world {world!r} here; accepted: {', '.join(self.worlds)}")
        return get_world(world)

    def check_task(self, world: str, shift: str, seed: int) -> World:
        """The world of a test task the page offers: one of its worlds, a shift of that world
        and a seed from 0 to MAX_SEED; else a UserError saying what is accepted."""
        w = self.offered(world)
        if shift not in w.shifts:
            accepted = ", ".join(w.shifts) or "none (it has no test tasks)"
            raise UserError(f"{world} has no shift {shift!r}; accepted: {accepted}")
        check_seed(seed)
        return w

    def pick(self, world: str, shift: str, seed: int) -> bool:
        """Load the failing test task of (world, shift, seed) and roll the base policy out."""
        w = self.check_task(world, shift, seed)

        def job() -> None:
            self.jobs.progress(0.1, f"loading the {world} base policy and finding the test task")
            policy = self.policies.get(w)
            task, _ = failing_test_task(w, policy, shift, seed)
            self.jobs.check()
            record = start(w, policy, task, shift=shift, seed=seed)
            self._commit(E.TaskLoaded(world, shift, seed, task.seed), record)
            self._notify({"stage"})

        return self._start("task", job, f"finding a {shift} task for seed {seed}")

    def next_task(self) -> bool:
        with self._lock:
            rec = self.record
        if rec is None:
            return self.pick(self.world_name, "object_ti", 0)
        shifts = get_world(rec.world).shifts
        if rec.shift not in shifts:  # a failure the sweep found: the world's first shift
            return self.pick(rec.world, shifts[0] if shifts else rec.shift, 0)
        return self.pick(rec.world, rec.shift, rec.seed + 1)

    def run_sweep(self, world: str, tasks: int) -> bool:
        """Sweep every single concept edit of `world`'s policy over `tasks` training tasks
        (the Sweep tab); the result is kept for the session's tabs, not logged."""
        w = self.offered(world)
        low, high = SWEEP_TASKS
        if isinstance(tasks, bool) or not isinstance(tasks, int) or not low <= tasks <= high:
            raise UserError(f"a sweep takes {low} to {high} tasks, not {tasks!r}")

        def job() -> None:
            from dfa_viz.sweep.run import page_sweep

            self.jobs.progress(0.05, f"loading the {world} policy")
            policy = self.policies.get(w)

            def on_progress(what: str, done: int, total: int) -> None:
                self.jobs.progress(done / max(total, 1), f"sweeping {what}: {done}/{total}")

            shown = page_sweep(w, policy, tasks, on_progress=on_progress)
            with self._lock:
                self.sweep = shown
            self._notify({"sweep"})

        return self._start("sweep", job, f"sweeping {tasks} {world} tasks")

    def load_failure(self, world: str, example) -> bool:
        """Load a failure the sweep found (search.sweep.Example: a training task and one
        edit) as the task to diagnose."""

        w = self.offered(world)

        def job() -> None:
            from search.sweep import failure_task

            self.jobs.progress(0.1, f"rolling the {world} policy out on task {example.seed}")
            policy = self.policies.get(w)
            task = failure_task(w, example)
            record = start(w, policy, task, shift=E.SWEEP, seed=example.seed)
            event = E.TaskLoaded(world, E.SWEEP, example.seed, task.seed, example.edit, example.pos)
            self._commit(event, record)
            self._notify({"stage"})

        return self._start("task", job, f"loading {example.edit} on task {example.seed}")

    def judge(self, failed: bool) -> None:
        with self._lock:
            E.need(self.record, "judge")
            self._commit(E.Judged(failed))
        self._notify({"stage"})

    def _demo_edit(self, fn: Callable[[DemoInput], None]) -> None:
        with self._lock:
            E.need(self.record, "demonstrate")
            if self.demo_input is None or self.busy:
                return
            fn(self.demo_input)
        self._notify({"demo"})

    def demo_click(self, u: float, v: float) -> None:
        self._demo_edit(lambda d: d.click(u, v))

    def demo_key(self, action: int) -> None:
        self._demo_edit(lambda d: d.act(action))

    def demo_undo(self) -> None:
        self._demo_edit(lambda d: d.undo())

    def demo_clear(self) -> None:
        self._demo_edit(lambda d: d.clear())

    def demonstrate(self, *, expert: bool = False, episode: int | None = None) -> bool:
        """Take the user's demonstration (or the expert's, or `episode` of the --demos dataset:
        one the page offers for this task), save it, and start the search. One that does not do
        what the task asks is refused, with the reason."""
        with self._lock:
            rec = E.need(self.record, "demonstrate")
            world = get_world(rec.world)
            d = self.demo_input
            if episode is not None:
                source, make = chosen(self.demos, world, rec.task, episode)
            else:
                source = "expert" if expert else (d.kind if d else "")
                if not expert and (d is None or not d.given()):
                    raise UserError("demonstrate first (or ask the expert)")
                if not expert and not d.ready():
                    raise UserError(d.problem())
                make = (lambda: world.demonstrate(rec.task)) if expert else d.trajectory

            def job() -> None:
                self.jobs.progress(0.0, "saving the demonstration")
                demo = make()
                require_success(rec.task, demo, source=f"the {source} demonstration")
                self.jobs.check()
                name = self.session.save_trajectory(demo, "demo")
                self._commit(E.Demonstrated(name, source), demo)
                self._notify({"stage"})
                self._search_job()

            return self._start("search", job, "saving the demonstration")

    def _search_job(self) -> None:
        with self._lock:
            rec = E.need(self.record, "diagnose")
        world = get_world(rec.world)

        def on_progress(size: int, done: int, total: int) -> None:
            self.jobs.progress(
                done / max(total, 1), f"searching edits of size {size}: {done}/{total}"
            )

        diagnosis = diagnose(
            world,
            self.policies.get(world),
            rec.task,
            rec.demo,
            config=SearchConfig.for_world(world),
            on_progress=on_progress,
        )
        self._commit(E.Searched(diagnosis.result), diagnosis)
        self._notify({"stage"})
        self.jobs.progress(1.0, "writing the recording")
        self.write_recording()

    def select_tie(self, index: int) -> None:
        with self._lock:
            rec = E.need(self.record, "feedback", "adapted")
            if index == rec.diagnosis.tie:
                return
            self._commit(E.TieChosen(index))  # an index out of range: refused, unwritten
        self._notify({"stage"})

    def mark(self, slot: str, concept: str, *, relevant: bool, acceptable: tuple[str, ...]) -> None:
        """Mark an edited concept TR, or TI with the instantiations that are acceptable."""
        with self._lock:
            rec = E.need(self.record, "feedback", "adapted")
            edited = [(c.slot, c.concept) for c in rec.edit.ordered] if rec.edit else []
            if (slot, concept) not in edited:  # e.g. a tab still showing another tie's marks
                shown = ", ".join(f"{s}.{c}" for s, c in edited) or "none"
                raise UserError(f"{slot}.{concept} is not an edited concept here: {shown}")
            current = rec.label(slot, concept)
            if (
                current is not None
                and current.relevant == relevant
                and (relevant or current.acceptable == tuple(acceptable))
            ):
                return
            label = Label(slot, concept, relevant, () if relevant else tuple(acceptable))
            self._commit(E.Marked(label))
        self._notify({"marks"})

    def finetuned(self) -> bool:
        """Whether the task was finetuned with the marks it has now (and these settings)."""
        with self._lock:
            rec = self.record
            done = rec is not None and rec.adaptation is not None
            return done and self._finetuned_with == (rec.feedback, self.adapt)

    def _finetunable(self) -> RunRecord:
        """The record to finetune: every edited concept marked, not finetuned with these marks
        yet (the same seed and marks would give the same policy again)."""
        rec = E.need(self.record, "feedback", "adapted")
        missing = rec.unmarked()
        if missing:
            raise UserError(f"mark {', '.join(missing)} as TI or TR first")
        if self.finetuned():
            raise UserError("finetuned with these marks already; change a mark to finetune again")
        return rec

    def finetune(self) -> bool:
        """Augment over the TI marks, finetune, evaluate; refused while a job runs."""
        with self._lock:
            if self.busy:
                return False
            rec = self._finetunable()
        world = get_world(rec.world)
        if self.policies.get(world).net is None:
            raise UserError(
                "this policy can be run but not trained (an ONNX graph): the diagnosis stands; "
                "give a PyTorch, stable-baselines3 or own checkpoint to finetune"
            )
        config = self.adapt
        steps = config.train_config(rec.seed).steps

        def job() -> None:
            self.losses = []
            last = [0.0]

            def on_loss(step: int, loss: float) -> None:
                self.jobs.check()  # stopping: end here
                self.losses.append(loss)
                now = time.monotonic()
                if now - last[0] > LOSS_NOTIFY_S or step + 1 == steps:
                    last[0] = now
                    self.jobs.progress(
                        0.9 * (step + 1) / steps,
                        f"finetuning: step {step + 1}/{steps}, loss {loss:.4f}",
                    )
                    self._notify({"losses"})

            self.jobs.progress(
                0.0, f"making up to {config.budget - 1} variants of the demonstration"
            )
            base = self.policies.get(world)
            adaptation = adapt(
                world,
                base,
                rec.task,
                rec.demo,
                rec.feedback,
                config=config,
                seed=rec.seed,
                known=self.policies.known(world),
                on_loss=on_loss,
            )
            self.jobs.progress(0.92, "scoring both policies on fresh tasks")
            evaluation = None  # a world without fresh tasks is not scored
            if world.benchmark:
                n = config.finetuning.n_eval
                evaluation = evaluate(world, base, adaptation.policy, rec.task, n=n, seed=rec.seed)
            self.jobs.check()
            rollout_file = self.session.save_trajectory(adaptation.rollout, "finetuned")
            policy_dir = self.session.next_name("policy")
            save_policy(
                adaptation.policy,
                self.session.folder / policy_dir,
                meta={"task_seed": rec.task.seed},
            )
            event = E.Finetuned(
                adaptation.feedback,
                len(adaptation.augmented),
                adaptation.losses,
                rollout_file,
                policy_dir,
                config,
                None if evaluation is None else evaluation.before,
                None if evaluation is None else evaluation.after,
            )
            self._commit(event, (adaptation, evaluation))
            self._notify({"stage"})
            self.jobs.progress(1.0, "writing the recording")
            self.write_recording()

        with self._lock:  # checked again and started at once: of two tabs, one starts it
            if self.busy:
                return False
            rec = self._finetunable()
            return self._start("finetune", job, "augmenting the demonstration")

    # -- recording ----------------------------------------------------------------------------
    def write_recording(self) -> Path | None:
        """(Re)write the task's .rrd under out/ when the state changed since the last write."""
        with self._record_lock:
            with self._lock:
                rec, version, path = self.record, self.content, self.recording
                if rec is None or path is None:
                    return None
                if self._recorded == version and path.exists():
                    return path
            write_recording(
                path, get_world(rec.world), dataclasses.replace(rec, recording=str(path))
            )
            with self._lock:
                self._recorded = version
            return path
