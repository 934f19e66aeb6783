"""The page's loop state, shared by every tab of one session: the user's actions on the run
(dfa_viz.app.runstate keeps the run, its log and its recording).

Algorithm 1 driven by the user, as the loop's own steps (dfa_viz.loop):
    pick -> judge -> demonstrate -> diagnose (search job) -> feedback -> adapt (finetune job)
(`solved` when the user says the rollout succeeded). Each action is one call of a loop step and
one event. Long jobs run one at a time (dfa_viz.app.jobs), each started under the lock that
checked it may start (two tabs pressing the same button start one job). The values of an action
are checked against what the page offers (dfa_viz.app.offers), whoever calls.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from dfa_viz.app import events as E
from dfa_viz.app import replay as R
from dfa_viz.app.demonstrate import DemoInput
from dfa_viz.app.episodes import chosen
from dfa_viz.app.runstate import RunState
from dfa_viz.app.view import View
from dfa_viz.loop import adapt_and_evaluate, diagnose, start
from dfa_viz.run_record import RunRecord
from policy import failing_test_task, save_policy
from policy.train import replays_rollouts
from search import SearchConfig
from sim.core import Label, UserError, World, require_success

LOSS_NOTIFY_S = 0.2  # at most this often while finetuning


class LoopState(RunState):
    """One session's loop, driven by the page; see the module docstring."""

    def resume(self) -> None:
        if self.record is not None and self.record.stage == "diagnose":
            self.jobs.start("search", self._search_job)  # the search was cut off: run it again

    # -- what the tabs draw -------------------------------------------------------------------
    def snapshot(self) -> View:
        with self._lock:
            rec, d = self.record, self.demo_input
            return View(
                version=self.version,
                world_name=self.world_name,
                world=self.world,
                record=rec,
                stage="pick" if rec is None else rec.stage,
                job=self.jobs.current,
                error=self.jobs.error,
                losses=tuple(self.losses),
                demo_kind=d.kind if d else "",
                demo_hint=d.hint if d else "",
                demo_summary=d.summary() if d else "",
                demo_given=d.given() if d else False,
                demo_ready=d.ready() if d else False,
                demo_problem=d.problem() if d else "",
                recording=self.recording,
                session=self.session.folder,
                adapt=self.adapt,
                finetuned=self.finetuned(),
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

    # -- user actions: each one loop step and one event ---------------------------------------
    def pick(self, world: str, shift: str, seed: int) -> bool:
        """Load the failing test task of (world, shift, seed) and roll the base policy out."""
        w = self.offers.task(world, shift, seed)

        def job() -> None:
            self.jobs.progress(0.1, f"loading the {world} base policy and finding the test task")
            policy = self.policies.get(w)
            task, _ = failing_test_task(w, policy, shift, seed)
            self.jobs.check()
            record = start(w, policy, task, shift=shift, seed=seed)
            self._commit(E.TaskLoaded(world, shift, seed, task.seed), record)

        return self._start("task", job, f"finding a {shift} task for seed {seed}")

    def offer_world(self, name: str) -> None:
        """List a world the user typed ("minigrid:<EnvId>", ...) in every tab's picker."""
        self.offers.typed(name)  # checked and built outside the lock
        with self._lock:  # then added to what another tab may have added meanwhile
            self.offers = self.offers.typed(name)
        self._notify({"worlds"})

    def next_task(self) -> bool:
        with self._lock:
            rec, world = self.record, self.world
        if rec is None or world is None:
            return self.pick(self.world_name, "object_ti", 0)
        if rec.shift not in world.shifts:  # a failure the sweep found: the world's first shift
            return self.pick(rec.world, world.shifts[0] if world.shifts else rec.shift, 0)
        return self.pick(rec.world, rec.shift, rec.seed + 1)

    def run_sweep(self, world: str, tasks: int) -> bool:
        """Sweep every single concept edit of `world`'s policy over `tasks` training tasks
        (the Sweep tab); the result is kept for the session's tabs, not logged."""
        w = self.offers.sweep(world, tasks)

        def job() -> None:
            from dfa_viz.sweep.run import page_sweep

            self.jobs.progress(0.05, f"loading the {world} policy")

            def on_progress(what: str, done: int, total: int) -> None:
                self.jobs.progress(done / max(total, 1), f"sweeping {what}: {done}/{total}")

            shown = page_sweep(w, self.policies.get(w), tasks, on_progress=on_progress)
            with self._lock:
                self.sweep = shown
            self._notify({"sweep"})

        return self._start("sweep", job, f"sweeping {tasks} {world} tasks")

    def load_failure(self, world: str, example) -> bool:
        """Load a failure the sweep found (search.sweep.Example: a training task and one
        edit) as the task to diagnose."""
        w = self.offers.world(world)

        def job() -> None:
            from search.sweep import failure_task

            self.jobs.progress(0.1, f"rolling the {world} policy out on task {example.seed}")
            task = failure_task(w, example)
            record = start(w, self.policies.get(w), task, shift=E.SWEEP, seed=example.seed)
            event = E.TaskLoaded(world, E.SWEEP, example.seed, task.seed, example.edit, example.pos)
            self._commit(event, record)

        return self._start("task", job, f"loading {example.edit} on task {example.seed}")

    def judge(self, failed: bool) -> None:
        with self._lock:
            R.need(self.record, "judge")
            self._commit(E.Judged(failed))

    def edit_demo(self, fn: Callable[[DemoInput], None]) -> None:
        """Apply a click, key, undo or clear (`fn`) to the demonstration being given."""
        with self._lock:
            R.need(self.record, "demonstrate")
            if self.demo_input is None or self.busy:
                return
            fn(self.demo_input)
        self._notify({"demo"})

    def demonstrate(self, *, expert: bool = False, episode: int | None = None) -> bool:
        """Take the user's demonstration (or the expert's, or `episode` of the --demos dataset:
        one the page offers for this task), save it, and start the search. One that does not do
        what the task asks is refused, with the reason."""
        with self._lock:
            rec, world, d = R.need(self.record, "demonstrate"), self.world, self.demo_input
            assert world is not None  # a task is loaded
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
                self._search_job()

            return self._start("search", job, "saving the demonstration")

    def _search_job(self) -> None:
        with self._lock:
            rec, world = R.need(self.record, "diagnose"), self.world
        assert world is not None  # a task is loaded

        def on_progress(size: int, done: int, total: int) -> None:
            self.jobs.progress(
                done / max(total, 1), f"searching edits of size {size}: {done}/{total}"
            )

        policy, config = self.policies.get(world), SearchConfig.for_world(world)
        assert rec.demo is not None  # the search comes after the demonstration
        diagnosis = diagnose(
            world, policy, rec.task, rec.demo, config=config, on_progress=on_progress
        )
        self._commit(E.Searched(diagnosis.result), diagnosis)
        self.jobs.progress(1.0, "writing the recording")
        self.write_recording()

    def select_tie(self, index: int) -> None:
        with self._lock:
            rec = R.need(self.record, *R.FEEDBACK)
            assert rec.diagnosis is not None  # the feedback stages come after the search
            if index != rec.diagnosis.tie:
                self._commit(E.TieChosen(index))  # an index out of range: refused, unwritten

    def mark(self, slot: str, concept: str, *, relevant: bool, acceptable: tuple[str, ...]) -> None:
        """Mark an edited concept TR, or TI with the instantiations that are acceptable."""
        with self._lock:
            rec = R.need(self.record, *R.FEEDBACK)
            edited = [(c.slot, c.concept) for c in rec.edit.ordered] if rec.edit else []
            if (slot, concept) not in edited:  # e.g. a tab still showing another tie's marks
                shown = ", ".join(f"{s}.{c}" for s, c in edited) or "none"
                raise UserError(f"{slot}.{concept} is not an edited concept here: {shown}")
            label = Label(slot, concept, relevant, () if relevant else tuple(acceptable))
            if rec.label(slot, concept) != label:
                self._commit(E.Marked(label), notify="marks")

    def _finetunable(self) -> tuple[RunRecord, World]:
        """The record to finetune: every edited concept marked, not finetuned with these marks
        yet (the same seed and marks would give the same policy again), a trainable policy."""
        rec, world = R.need(self.record, *R.FEEDBACK), self.world
        assert world is not None  # a task is loaded
        missing = rec.unmarked()
        if missing:
            raise UserError(f"mark {', '.join(missing)} as TI or TR first")
        if self.finetuned():
            raise UserError("finetuned with these marks already; change a mark to finetune again")
        if self.policies.get(world).net is None:
            raise UserError(
                "this policy can be run but not trained (an ONNX graph): the diagnosis stands; "
                "give a PyTorch, stable-baselines3 or own checkpoint to finetune"
            )
        return rec, world

    def finetune(self) -> bool:
        """Augment over the TI marks, finetune, evaluate; refused while a job runs."""
        with self._lock:  # checked and started at once: of two tabs, one starts it
            if self.busy:
                return False
            rec, world = self._finetunable()
            job = lambda: self._finetune_job(rec, world)  # noqa: E731
            return self._start("finetune", job, "augmenting the demonstration")

    def _finetune_job(self, rec: RunRecord, world: World) -> None:
        config, steps, last = self.adapt, self.adapt.total_steps, [0.0]
        self.losses = []

        def on_loss(step: int, loss: float) -> None:
            self.jobs.check()  # stopping: end here
            self.losses.append(loss)
            if time.monotonic() - last[0] > LOSS_NOTIFY_S or step + 1 == steps:
                last[0] = time.monotonic()
                text = f"finetuning: step {step + 1}/{steps}, loss {loss:.4f}"
                self.jobs.progress(0.9 * (step + 1) / steps, text)
                self._notify({"losses"})

        making = f"making up to {config.budget - 1} variants of the demonstration"
        if replays_rollouts(world) and config.finetuning.replay_share > 0:
            making = f"rolling the base policy out on its training tasks to replay, {making}"
        self.jobs.progress(0.0, making)
        base = self.policies.get(world)
        adaptation, evaluation = adapt_and_evaluate(
            world,
            base,
            rec,
            config=config,
            known=self.policies.known(world) if config.finetuning.uses_training_demos else (),
            on_loss=on_loss,
            on_scoring=lambda: self.jobs.progress(0.92, "scoring both policies on fresh tasks"),
        )
        self.jobs.check()
        rollout_file = self.session.save_trajectory(adaptation.rollout, "finetuned")
        policy_dir = self.session.next_name("policy")
        meta = {"task_seed": rec.task.seed}
        save_policy(adaptation.policy, self.session.folder / policy_dir, meta=meta)
        event = E.Finetuned(
            feedback=adaptation.feedback,
            n_augmented=len(adaptation.augmented),
            losses=adaptation.losses,
            rollout_file=rollout_file,
            policy_dir=policy_dir,
            config=config,
            before=None if evaluation is None else evaluation.before,
            after=None if evaluation is None else evaluation.after,
        )
        self._commit(event, (adaptation, evaluation))
        self.jobs.progress(1.0, "writing the recording")
        self.write_recording()
