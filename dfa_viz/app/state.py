"""The page's loop state, shared by every tab of one session.

Algorithm 1 as a state machine driven by the user:
    pick -> judge -> demonstrate -> diagnose (search job) -> feedback -> adapt (finetune job)
(`solved` when the user says the rollout succeeded). Each user action is appended to the
session log (flushed and fsynced) before the state changes and the tabs are told; replaying
the log rebuilds the same state, so a restart with the same session resumes where it stopped.

Thread-safety: every read and write of the state holds `self._lock`; long jobs run on one
worker thread at a time (a second start while one runs is refused, harmlessly); subscribers
(the tabs) are called outside the lock with the set of things that changed.
"""

from __future__ import annotations

import itertools
import queue
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from dfa_viz.app import work
from dfa_viz.app.demonstrate import DemoInput
from dfa_viz.app.events import apply_event
from dfa_viz.app.run import Job, Run, View, need
from dfa_viz.app.sessions import Session, SessionError
from dfa_viz.app.work import Policies
from sim.core import UserError, require_success

Listener = Callable[[set[str]], None]
LOSS_NOTIFY_S = 0.2  # at most this often while finetuning


class LoopState:
    """One session's loop, driven by the page; see the module docstring."""

    def __init__(
        self,
        session: Session,
        *,
        out: Path = Path("recordings"),
        finetune_steps: int | None = None,
        policies: Policies | None = None,
    ) -> None:
        self.session = session
        self.out = Path(out)
        self.finetune_steps = finetune_steps or work.FINETUNE.steps
        self.policies = policies or Policies()
        self.world_name = session.world
        self.run: Run | None = None
        self.demo_input: DemoInput | None = None
        self.job: Job | None = None
        self.error = ""
        self.losses: list[float] = []  # live, while finetuning
        self.version = 0  # bumps on every notification
        self.content = 0  # bumps on every committed event (what the recording shows)
        self.recording: Path | None = None
        self._recorded = -1
        self._lock = threading.RLock()
        self._record_lock = threading.Lock()
        self._listeners: dict[int, Listener] = {}
        self._ids = itertools.count()
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
        """Stop taking input and release the session folder (a running job is abandoned; its
        event was not written, so a restart redoes or offers it again)."""
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

    # -- applying events (live and on replay) -------------------------------------------------
    def _replay(self) -> None:
        for event in self.session.events[1:]:
            try:
                apply_event(self, event)
            except UserError as e:
                if isinstance(e, SessionError):
                    raise
                raise SessionError(f"{self.session.path}:{event['_line']}: {e}") from None
        if self.run is not None and self.run.stage == "diagnose":
            self._start("search", self._search_job)  # the search was cut off: run it again

    def _commit(self, kind: str, computed=None, **fields) -> None:
        """Append the event durably, then apply it (all under the state lock)."""
        with self._lock:
            ev = self.session.append(kind, **fields)
            apply_event(self, ev, computed)
            self.content += 1

    def _policy(self, run: Run):
        return self.policies.get(run.world)

    # -- jobs ---------------------------------------------------------------------------------
    def _start(self, name: str, fn: Callable[[], None], text: str = "") -> bool:
        with self._lock:
            if self.job is not None:
                return False  # one job at a time; a second click does nothing
            self.job = Job(name, 0.0, text or f"{name}…")
            self.error = ""
        threading.Thread(target=self._run_job, args=(fn,), name=f"dfa-{name}", daemon=True).start()
        self._notify({"job"})
        return True

    def _run_job(self, fn: Callable[[], None]) -> None:
        try:
            fn()
        except UserError as e:
            with self._lock:
                self.error = str(e)
        except Exception as e:  # shown on the page; the server keeps running
            traceback.print_exc()
            with self._lock:
                self.error = f"{type(e).__name__}: {e}"
        finally:
            with self._lock:
                self.job = None
            self._notify({"job", "stage", "error"})

    def _progress(self, progress: float, text: str) -> None:
        with self._lock:
            if self.job is not None:
                self.job = Job(self.job.name, max(0.0, min(1.0, progress)), text)
        self._notify({"job"})

    def snapshot(self) -> View:
        with self._lock:
            run = self.run
            copy = None
            if run is not None:
                copy = Run(**{**run.__dict__, "marks": dict(run.marks)})
            d = self.demo_input
            return View(
                self.version,
                self.world_name,
                copy,
                "pick" if run is None else run.stage,
                self.job,
                self.error,
                tuple(self.losses),
                d.kind if d else "",
                d.hint if d else "",
                d.summary() if d else "",
                d.ready() if d else False,
                d.problem() if d else "",
                self.recording,
                self.session.folder,
            )

    def demo_canvas(self):
        """uint8 (H, W, 3): the demonstration canvas, or the task's first frame; None before
        a task is picked."""
        with self._lock:
            if (
                self.demo_input is not None
                and self.run is not None
                and self.run.stage == "demonstrate"
            ):
                return self.demo_input.canvas()
            if self.run is None:
                return None
            from dfa_viz.app import frames

            k = frames.scale_for(self.run.world.obs_shape, frames.CANVAS_PX)
            return frames.upscale(self.run.rollout.observations[0], k)

    def demo_keys(self):
        with self._lock:
            return self.demo_input.keys if self.demo_input is not None else ()

    @property
    def busy(self) -> bool:
        with self._lock:
            return self.job is not None

    # -- user actions -------------------------------------------------------------------------
    def pick(self, world: str, shift: str, seed: int) -> bool:
        """Load the failing test task of (world, shift, seed) and roll the base policy out."""

        def job() -> None:
            self._progress(0.1, f"loading the {world} base policy and finding the test task")
            computed = work.pick_task(world, shift, seed, self.policies)
            self._commit(
                "task",
                computed,
                world=world,
                shift=shift,
                seed=seed,
                task_seed=computed[1].seed,
            )
            self._notify({"stage"})

        return self._start("task", job, f"finding a {shift} task for seed {seed}")

    def next_task(self) -> bool:
        with self._lock:
            run = self.run
        if run is None:
            return self.pick(self.world_name, "object_ti", 0)
        return self.pick(run.world.name, run.shift, run.seed + 1)

    def judge(self, failed: bool) -> None:
        with self._lock:
            need(self.run, "judge")
            self._commit("judgement", failed=failed)
        self._notify({"stage"})

    def _demo_edit(self, fn: Callable[[DemoInput], None]) -> None:
        with self._lock:
            need(self.run, "demonstrate")
            if self.demo_input is None or self.job is not None:
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

    def demonstrate(self, *, expert: bool) -> bool:
        """Take the user's demonstration (or the expert's), save it, and start the search."""
        with self._lock:
            run = need(self.run, "demonstrate")
            source = "expert" if expert else (self.demo_input.kind if self.demo_input else "")
            if not expert and (self.demo_input is None or not self.demo_input.given()):
                raise UserError("demonstrate first (or ask the expert)")
            if not expert and not self.demo_input.ready():
                raise UserError(self.demo_input.problem())
            make = (
                (lambda: run.world.demonstrate(run.task)) if expert else self.demo_input.trajectory
            )

        def job() -> None:
            self._progress(0.0, "saving the demonstration")
            demo = make()
            require_success(run.task, demo, source=f"the {source} demonstration")
            name = self.session.save_trajectory(demo, "demo")
            self._commit("demonstration", demo, file=name, source=source)
            self._notify({"stage"})
            self._search_job()

        return self._start("search", job, "saving the demonstration")

    def _search_job(self) -> None:
        with self._lock:
            run = need(self.run, "diagnose")

        def on_progress(size: int, done: int, total: int) -> None:
            self._progress(done / max(total, 1), f"searching edits of size {size}: {done}/{total}")

        policy = self._policy(run)
        result = work.search(run.world, policy, run.task, run.demo, on_progress=on_progress)
        cfs = work.counterfactual_rollouts(run.world, policy, run.task, result)
        self._commit("search", (result, cfs), **work.search_to_json(result))
        self._notify({"stage"})
        self._progress(1.0, "writing the recording")
        self.write_recording()

    def select_tie(self, index: int) -> None:
        with self._lock:
            run = need(self.run, "feedback", "adapted")
            if index == run.tie:
                return
            self._commit("tie", index=index)
        self._notify({"stage"})

    def mark(self, slot: str, concept: str, *, relevant: bool, acceptable: tuple[str, ...]) -> None:
        """Mark an edited concept TR, or TI with the instantiations that are acceptable."""
        with self._lock:
            run = need(self.run, "feedback", "adapted")
            label = "TR" if relevant else "TI"
            current = run.marks.get((slot, concept))
            if (
                current is not None
                and current.relevant == relevant
                and (relevant or current.acceptable == tuple(acceptable))
            ):
                return
            self._commit(
                "mark", slot=slot, concept=concept, label=label, acceptable=list(acceptable)
            )
        self._notify({"marks"})

    def finetune(self) -> bool:
        """Augment over the TI marks, finetune, evaluate; refused while a job runs."""
        with self._lock:
            run = need(self.run, "feedback", "adapted")
            missing = run.unmarked()
            if missing:
                raise UserError(f"mark {', '.join(missing)} as TI or TR first")
            feedback = work.feedback_for(run.edit, run.marks)
            if self.job is not None:
                return False

        def job() -> None:
            self.losses = []
            last = [0.0]

            def on_loss(step: int, loss: float) -> None:
                self.losses.append(loss)
                now = time.monotonic()
                if now - last[0] > LOSS_NOTIFY_S or step + 1 == self.finetune_steps:
                    last[0] = now
                    self._progress(
                        0.9 * (step + 1) / self.finetune_steps,
                        f"finetuning: step {step + 1}/{self.finetune_steps}, loss {loss:.4f}",
                    )
                    self._notify({"losses"})

            adaptation = work.adapt(
                run.world,
                self._policy(run),
                run.task,
                run.demo,
                feedback,
                seed=run.seed,
                steps=self.finetune_steps,
                on_loss=on_loss,
                on_phase=lambda text: self._progress(self.job.progress if self.job else 0, text),
            )
            fields = work.save_adaptation(self.session, adaptation, run.task)
            self._commit("finetune", adaptation, **fields)
            self._notify({"stage"})
            self._progress(1.0, "writing the recording")
            self.write_recording()

        return self._start("finetune", job, "augmenting the demonstration")

    # -- recording ----------------------------------------------------------------------------
    def write_recording(self) -> Path | None:
        """(Re)write the task's .rrd under out/ when the state changed since the last write."""
        with self._record_lock:
            with self._lock:
                run, version, path = self.run, self.content, self.recording
                if run is None or path is None:
                    return None
                if self._recorded == version and path.exists():
                    return path
                args = dict(
                    rollout=run.rollout,
                    demo=run.demo,
                    result=run.result,
                    tie=run.tie,
                    counterfactual=run.counterfactual,
                    adaptation=run.adaptation,
                    seed=run.seed,
                )
            work.write_recording(path, run.world, run.task, **args)
            with self._lock:
                self._recorded = version
            return path
