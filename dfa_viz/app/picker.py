"""The demonstrate step's dataset picker of one tab (`dfa serve --demos DIR`): a line on what the
dataset offers for the task, a dropdown of those episodes and a button that uses the chosen one
as the demonstration (LoopState.demonstrate(episode=N), checked there again against what is
offered for the task loaded now). Hidden when the page was served without a dataset."""

from __future__ import annotations

import viser

from dfa_viz.app.controls import Checked, one_of
from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View
from sim.core import UserError

USE_EPISODE = "Use the dataset episode"  # contains no other button's name, nor they it
NONE = "—"


class EpisodePicker:
    def __init__(self, client: viser.ClientHandle, state: LoopState, guard) -> None:
        self.state = state
        self._labels: tuple[str, ...] = ()  # the episodes offered now, as the dropdown names them
        self._index: dict[str, int] = {}
        self._shown_for: int | None = None
        gui = client.gui
        self.note = gui.add_markdown("", visible=False)
        dropdown = gui.add_dropdown("dataset episode", (NONE,), visible=False)
        self.episode = Checked(dropdown, one_of(lambda: self._labels or (NONE,)), client)
        self.use = gui.add_button(USE_EPISODE, icon=viser.Icon.DATABASE, visible=False)
        self.use.on_click(guard(lambda _: self._use()))

    def _use(self) -> bool:
        label = self.episode.value
        if label not in self._index:
            raise UserError("choose an episode of the dataset first")
        return self.state.demonstrate(episode=self._index[label])

    def refresh(self, view: View) -> None:
        demos, run = self.state.demos, view.record
        shown = demos is not None and run is not None and view.stage == "demonstrate"
        for handle in (self.note, self.episode.handle, self.use):
            handle.visible = shown
        if not shown:
            return
        if id(run.task) != self._shown_for:  # the episodes offered change with the task only
            self._shown_for = id(run.task)
            offered = demos.offered(run.task)
            self._index = {e.label: e.index for e in offered}
            labels = tuple(self._index)
            if labels != self._labels:
                self._labels = labels  # first: the dropdown may take its first option at once
                self.episode.handle.options = labels or (NONE,)
            self.episode.set(labels[0] if labels else NONE)
            self.note.content = demos.describe(run.task)
        self.use.disabled = view.job is not None or not self._labels
