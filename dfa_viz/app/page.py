"""One tab's page: the control panel (task, judge, demonstrate, diagnose, feedback, adapt,
share), the compare panel and the 3D canvas, all drawn from the shared LoopState.

Built in on_client_connect; every tab of a session subscribes to the same state, so what one
tab does the others show at once. Every value a tab sets is checked against what the page
offered (dfa_viz.app.controls) before anything reads it.
"""

from __future__ import annotations

import threading
import traceback

import viser

from dfa_viz.app import plots
from dfa_viz.app.canvas import Canvas
from dfa_viz.app.compare import ComparePanel
from dfa_viz.app.controls import Checked, hidden, one_of
from dfa_viz.app.feedback import FeedbackSection
from dfa_viz.app.picker import EpisodePicker
from dfa_viz.app.state import LoopState
from dfa_viz.app.sweep import SweepTab
from dfa_viz.app.tables import diagnosis_text, edit_table, results_text, status_text
from dfa_viz.app.task_section import TaskSection
from dfa_viz.app.view import View
from sim.core import UserError

PANEL_PX = 360  # the control panel's width; the compare panel takes the right side
# the next action's labels (none contains another button's name: tests find buttons by name)
USE_DEMO, ASK_EXPERT = "Continue: search with my demonstration", "Continue: the expert shows it"
FINETUNE, NEXT_TASK = "Continue: make variants and finetune", "Continue: another task"


class Page:
    def __init__(self, client: viser.ClientHandle, state: LoopState):
        self.client, self.state = client, state
        self._lock = threading.RLock()
        self._commands: list = []
        self._keys_for: int | None = None
        self._ties: tuple[str, ...] = ()  # the minimal edits offered, as the dropdown names them
        gui = client.gui
        client.gui.main_panel.dock_left()
        client.gui.main_panel.set_width(PANEL_PX)
        self.header = gui.add_markdown("### DFA — diagnose, feedback, adapt")
        # what to do next, why it waits and the running job: a panel of their own above the
        # control panel, in view at every window size whatever is scrolled below; a button per
        # next step, one shown at a time (a press names no label, so a press of a step that is
        # over, arriving late, finds its own button hidden, never the next one's)
        self.next_panel = gui.add_panel()
        with self.next_panel.add_tab("Next step", icon=viser.Icon.ARROW_RIGHT):
            self.status = gui.add_markdown("")
            self.error = gui.add_markdown("", visible=False)
            self.primary = {
                label: gui.add_button(label, icon=viser.Icon.ARROW_RIGHT, visible=False)
                for label in (USE_DEMO, ASK_EXPERT, FINETUNE, NEXT_TASK)
            }
            # judging is a choice of two: both buttons, while the policy's rollout is judged
            self.failed = gui.add_button("Failed", color="red", icon=viser.Icon.X, visible=False)
            self.succeeded = gui.add_button(
                "Succeeded", color="green", icon=viser.Icon.CHECK, visible=False
            )
            self.reason = gui.add_markdown("", visible=False)
            self.job_bar = gui.add_progress_bar(0, animated=True, visible=False)
        self.next_panel.dock_above(client.gui.main_panel)
        self._stage_shown: str | None = None

        self.task = TaskSection(client, state, self._guard)

        self.demo_folder = gui.add_folder("2 · Demonstrate", visible=False)
        with self.demo_folder:
            self.demo_hint = gui.add_markdown("")
            self.demo_summary = gui.add_markdown("")
            self.keys_holder = gui.add_folder("actions", visible=False)
            self.use_demo = gui.add_button("Use my demonstration", icon=viser.Icon.CHECK)
            self.undo = gui.add_button("Undo", icon=viser.Icon.ARROW_BACK_UP)
            self.clear = gui.add_button("Clear", icon=viser.Icon.TRASH)
            self.expert = gui.add_button("Ask the expert", icon=viser.Icon.ROBOT)
            self.picker = EpisodePicker(client, state, self._guard)  # dfa serve --demos

        self.diag_folder = gui.add_folder("3 · Diagnose", visible=False)
        with self.diag_folder:
            self.diagnosis = gui.add_markdown("")
            tie = gui.add_dropdown("minimal edit", ("—",), visible=False)
            self.tie = Checked(tie, one_of(lambda: self._ties or ("—",)), client, self._on_tie)
            self.delta = gui.add_markdown("")

        self.feedback = FeedbackSection(client, state, self.warn)

        self.adapt_folder = gui.add_folder("5 · Adapt", visible=False)
        with self.adapt_folder:
            self.finetune = gui.add_button("Augment & finetune", icon=viser.Icon.BOLT)
            steps = state.adapt.total_steps
            data, series, scales, axes = plots.loss_plot([], steps)
            self.loss = gui.add_uplot(
                data,
                series,
                scales=scales,
                axes=axes,
                title="finetuning loss",
                aspect=2.0,
                visible=False,
            )
            self.results = gui.add_markdown("")

        with gui.add_folder("6 · Share"):
            self.download = gui.add_button("Download .rrd", icon=viser.Icon.DOWNLOAD)
            self.share = gui.add_markdown("")

        self.compare = ComparePanel(client, state, on_step=self._on_step)
        self.canvas = Canvas(client, state, self.warn)
        self.sweep = SweepTab(
            client,
            state,
            self.compare.panel,
            self.canvas,
            world=lambda: self.task.world.value,
            warn=self.warn,
        )
        self._wire()
        self.unsubscribe = state.subscribe(self.on_change)
        self.on_change({"all"})

    # -- events -------------------------------------------------------------------------------
    def warn(self, text: str) -> None:
        self.client.add_notification("Not now", text, color="yellow", auto_close_seconds=6.0)

    def _guard(self, fn):
        def run(event) -> None:
            if event.client is not None and hidden(self.client, event.target):
                return  # a press the page does not offer now (a forged one, or late)
            try:
                if fn(event) is False:
                    self.warn("a job is running; wait for it to finish")
            except UserError as e:
                self.warn(str(e))
            except Exception as e:
                traceback.print_exc()
                self.warn(f"{type(e).__name__}: {e}")

        return run

    def _wire(self) -> None:
        s = self.state
        self.failed.on_click(self._guard(lambda _: s.judge(True)))
        self.succeeded.on_click(self._guard(lambda _: s.judge(False)))
        self.use_demo.on_click(self._guard(lambda _: s.demonstrate(expert=False)))
        self.expert.on_click(self._guard(lambda _: s.demonstrate(expert=True)))
        self.undo.on_click(self._guard(lambda _: s.edit_demo(lambda d: d.undo())))
        self.clear.on_click(self._guard(lambda _: s.edit_demo(lambda d: d.clear())))
        self.finetune.on_click(self._guard(lambda _: s.finetune()))
        for label, button in self.primary.items():
            button.on_click(self._guard(lambda _, label=label: self._on_primary(label)))
        self.download.on_click(self._guard(self._download))

    def _on_tie(self, event) -> None:
        if event.client is None or self.tie.value not in self._ties:
            return  # set by the page, or the placeholder
        index = self._ties.index(self.tie.value)
        self._guard(lambda _: self.state.select_tie(index))(event)

    def _download(self, _event) -> None:
        path = self.state.write_recording()
        if path is None:
            raise UserError("pick a task first: there is nothing recorded yet")
        self.client.send_file_download(path.name, path.read_bytes(), save_immediately=True)

    def _on_step(self, view: View, step: int) -> None:
        self.canvas.show_scenes(view, step)

    # -- drawing ------------------------------------------------------------------------------
    def on_change(self, what: set[str]) -> None:
        with self._lock, self.client.atomic():
            # read inside the lock: a notification drawn after another never draws older state
            view = self.state.snapshot()
            self._draw_controls(view)
            if what & {"all", "stage", "marks", "demo"}:
                self.feedback.refresh(view)
                self._draw_diagnosis(view)
                self._draw_keys(view)
                self.canvas.refresh(view, force="all" in what)
                self.compare.refresh(view)
            if what & {"all", "stage", "marks", "losses", "job"}:
                self._draw_adapt(view)
            self.sweep.refresh(busy=view.job is not None)
        self.client.flush()

    def _draw_controls(self, view: View) -> None:
        busy = view.job is not None
        run, stage = view.record, view.stage
        self.task.draw(view)
        self.status.content = status_text(view)
        self.error.content = f"**Error:** {view.error}" if view.error else ""
        self.error.visible = bool(view.error)
        job = view.job
        self.job_bar.visible = job is not None
        if job is not None:
            self.job_bar.value = round(100 * job.progress, 1)
        for b in (self.failed, self.succeeded):
            b.visible = run is not None and stage == "judge"
            b.disabled = busy
        self.demo_folder.visible = run is not None and stage == "demonstrate"
        self.demo_hint.content = view.demo_hint
        summary = f"*{view.demo_summary}*" if view.demo_summary else ""
        if view.demo_problem:
            summary += f"\n\n⚠ {view.demo_problem}"
        self.demo_summary.content = summary
        clicks_or_keys = view.demo_kind in ("clicks", "keys")
        for b in (self.use_demo, self.undo, self.clear):
            b.visible = clicks_or_keys
            b.disabled = busy
        self.use_demo.disabled = busy or not view.demo_ready
        self.expert.disabled = busy
        self.picker.refresh(view)
        self.diag_folder.visible = run is not None and stage in ("diagnose", "feedback", "adapted")
        self.adapt_folder.visible = run is not None and stage in ("feedback", "adapted")
        unmarked = run is not None and bool(run.unmarked())
        self.finetune.disabled = busy or view.finetuned or unmarked
        self.download.disabled = run is None
        self._draw_primary(view)
        if stage != self._stage_shown:  # give the demonstration image the room it needs
            self._stage_shown = stage
            if stage == "demonstrate":
                self.compare.panel.minimize()
            else:
                self.compare.panel.expand()
        rec = view.recording
        self.share.content = (
            f"Recording: `{rec}`  \nSession: `{view.session}`"
            if rec is not None
            else f"Session: `{view.session}`"
        )

    def _next_action(self, view: View) -> tuple[str, str] | None:
        """The active stage's primary action (label, why it waits: "" when it may be pressed),
        or None where there is none."""
        run = view.record
        if run is None or view.stage == "solved":
            return None
        busy = "wait until the job above ends" if view.job is not None else ""
        if view.stage == "demonstrate":
            if view.demo_kind in ("clicks", "keys") and view.demo_given:
                return USE_DEMO, busy or (
                    "" if view.demo_ready else view.demo_problem or "not done"
                )
            return ASK_EXPERT, busy
        if view.stage == "feedback":
            unmarked = run.unmarked()
            return FINETUNE, busy or (f"mark {', '.join(unmarked)} first" if unmarked else "")
        if view.stage == "adapted":
            return NEXT_TASK, busy
        return None

    def _draw_primary(self, view: View) -> None:
        label, why = self._next_action(view) or ("", "")
        for name, button in self.primary.items():
            button.visible = name == label
            button.disabled = not (name == label and not why)
        self.reason.content = f"*{why[0].upper()}{why[1:]}.*" if why else ""
        self.reason.visible = bool(why)

    def _on_primary(self, label: str):
        action = self._next_action(self.state.snapshot())
        if action is None or action[0] != label:
            raise UserError(f"{label}: that step is over")  # pressed as the page moved on
        if action[1]:
            return False if self.state.busy else None
        s = self.state
        return {
            USE_DEMO: lambda: s.demonstrate(expert=False),
            ASK_EXPERT: lambda: s.demonstrate(expert=True),
            FINETUNE: s.finetune,
            NEXT_TASK: s.next_task,
        }[label]()

    def _draw_diagnosis(self, view: View) -> None:
        run = view.record
        if run is None:
            return
        self.diagnosis.content = diagnosis_text(view)
        edit = run.edit
        self.delta.content = edit_table(view.world, run.task.scene, edit) if edit else ""
        ties: tuple[str, ...] = ()
        d = run.diagnosis
        if d is not None and d.result.found:
            ties = tuple(
                f"{i + 1}. {c.edit}"
                for i, c in enumerate(d.result.counterfactuals[: len(d.counterfactuals)])
            )
        self.tie.handle.visible = len(ties) > 1
        if ties != self._ties:
            self._ties = ties  # first: the dropdown may take its first option at once
            self.tie.handle.options = ties or ("—",)
        if ties:
            self.tie.set(ties[d.tie])

    def _draw_adapt(self, view: View) -> None:
        run = view.record
        if run is None:
            return
        losses = view.losses if view.job is not None and view.job.name == "finetune" else ()
        if not losses and run.adaptation is not None:
            losses = run.adaptation.losses
        self.loss.visible = bool(losses)
        if losses:
            data, _, scales, axes = plots.loss_plot(losses, view.adapt.total_steps)
            self.loss.scales, self.loss.axes = scales, axes
            self.loss.data = data
        self.results.content = results_text(view)

    def _draw_keys(self, view: View) -> None:
        """Buttons and hotkeys for worlds demonstrated with keys (doorkey)."""
        run = view.record
        want = id(run.task) if run is not None and view.stage == "demonstrate" else None
        keys = self.state.demo_keys() if want is not None else ()
        if (want if keys else None) == self._keys_for:
            return
        self._keys_for = want if keys else None
        for handle in self._commands:
            handle.remove()
        self._commands = []
        self.keys_holder.visible = bool(keys)
        if not keys:
            return
        gui = self.client.gui
        with self.keys_holder:
            for key in keys:
                button = gui.add_button(key.label, hint=f"key: {key.hotkey}")
                button.on_click(self._key_handler(key.action))
                self._commands.append(button)
        for key in keys:
            cmd = gui.add_command(key.label, hotkey=key.hotkey)
            cmd.on_trigger(self._key_handler(key.action))
            self._commands.append(cmd)

    def _key_handler(self, action: int):
        async def on_key(_event) -> None:  # on the event loop: keys keep their order
            self.state.submit(lambda: self.state.edit_demo(lambda d: d.act(action)), self.warn)

        return on_key

    def close(self) -> None:
        self.unsubscribe()
        self.compare.close()
