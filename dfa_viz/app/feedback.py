"""The feedback controls of one tab: for each concept the selected edit changes, a TI / TR
choice and, for TI, which instantiations are acceptable. Rebuilt when the edit changes;
synced from the shared state when another tab marks something."""

from __future__ import annotations

import viser

from dfa_viz.app.controls import Checked, hidden, one_of, refusal, refuse
from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View
from sim.core import Change, ConceptSpace, Label, UserError

TI = "Task-irrelevant (TI)"
TR = "Task-relevant (TR)"
MAX_CHECKBOXES = 12  # above this many instantiations, a compact picker
ALL, EDIT_ONLY = "all of them", "only the two shown"
NOT_CHOSEN = "—"


class MarkControls:
    """The controls for one edited concept: two answer buttons (the chosen one marked ✔ and
    coloured), and for TI which instantiations are fine: checkboxes for a few, a compact
    picker for many (all / only the two shown, leave one out, put one back)."""

    def __init__(
        self,
        client: viser.ClientHandle,
        state: LoopState,
        change: Change,
        space: ConceptSpace,
        warn,
    ) -> None:
        self.client, self.state, self.change, self.warn = client, state, change, warn
        gui = client.gui
        self.space = space
        self.values = space.values(change.slot, change.concept)
        self.key = (change.slot, change.concept)
        name = f"{change.slot}.{change.concept}"
        gui.add_markdown(f"**{name}**: {change.old} → {change.new}")
        self.ti = gui.add_button(TI, color="gray", hint="the policy should ignore it")
        self.tr = gui.add_button(TR, color="gray", hint="the policy is right to care")
        self.status = gui.add_markdown("not marked yet")
        self.boxes: dict[str, viser.GuiCheckboxHandle] = {}
        self.preset = self.leave_out = self.put_back = None
        self._acceptable: tuple[str, ...] = self.values
        # what the two pickers offer now (a tab may send anything)
        self._leave_offered: tuple[str, ...] = (NOT_CHOSEN, *self.values)
        self._back_offered: tuple[str, ...] = (NOT_CHOSEN,)
        if len(self.values) <= MAX_CHECKBOXES:
            for v in self.values:
                box = gui.add_checkbox(f"{v}", True, hint=f"{name} = {v} is fine", visible=False)
                box.on_update(self._on_box)
                self.boxes[v] = box
        else:
            self.preset = gui.add_button_group("fine", (ALL, EDIT_ONLY), visible=False)
            leave_out = gui.add_dropdown("leave out", self._leave_offered, visible=False)
            put_back = gui.add_dropdown("put back", self._back_offered, visible=False)
            self.preset.on_click(self._on_preset)
            self.leave_out = Checked(
                leave_out, one_of(lambda: self._leave_offered), client, self._on_leave_out
            )
            self.put_back = Checked(
                put_back, one_of(lambda: self._back_offered), client, self._on_put_back
            )
        self.ti.on_click(lambda _: self._answer(relevant=False))
        self.tr.on_click(lambda _: self._answer(relevant=True))

    def acceptable(self) -> tuple[str, ...]:
        if self.boxes:
            return tuple(v for v, box in self.boxes.items() if box.value)
        return self._acceptable

    def _answer(self, *, relevant: bool) -> None:
        try:
            acceptable = () if relevant else (self.acceptable() or self.values)
            self.state.mark(*self.key, relevant=relevant, acceptable=acceptable)
        except UserError as e:
            self.warn(str(e))

    def _set(self, acceptable: tuple[str, ...]) -> None:
        """Mark TI with these instantiations (at least one is kept)."""
        if not acceptable:
            self.warn("keep at least one acceptable instantiation, or mark the concept TR")
            self.sync(self.state.snapshot().record.label(*self.key))
            return
        try:
            self.state.mark(*self.key, relevant=False, acceptable=acceptable)
        except UserError as e:
            self.warn(str(e))

    def _on_box(self, event) -> None:
        if event.client is None:
            return  # set from the shared state, not by this user
        if hidden(self.client, event.target):  # shown only while marked TI
            event.target.value = not event.target.value  # a tab's change is always a flip
            return
        self._set(self.acceptable())

    def _on_preset(self, event) -> None:
        if hidden(self.client, event.target):
            return
        if event.target.value not in (ALL, EDIT_ONLY):
            why = f"accepted: {ALL}, {EDIT_ONLY}"
            refuse(self.client, refusal("fine", event.target.value, why))
            return
        both = {self.change.old, self.change.new}
        chosen = (
            self.values if event.target.value == ALL else tuple(v for v in self.values if v in both)
        )
        self._set(chosen)

    def _on_leave_out(self, event) -> None:
        value = self.leave_out.value
        if event.client is None or value == NOT_CHOSEN:
            return
        self._set(tuple(v for v in self._acceptable if v != value))

    def _on_put_back(self, event) -> None:
        value = self.put_back.value
        if event.client is None or value == NOT_CHOSEN:
            return
        keep = set(self._acceptable) | {value}
        self._set(tuple(v for v in self.values if v in keep))

    def sync(self, label: Label | None) -> None:
        """Show the shared mark (set by this tab or another)."""
        ti = label is not None and not label.relevant
        tr = label is not None and label.relevant
        self.ti.label, self.ti.color = (f"✔ {TI}", "green") if ti else (TI, "gray")
        self.tr.label, self.tr.color = (f"✔ {TR}", "orange") if tr else (TR, "gray")
        if label is None:
            self.status.content = "not marked yet"
        elif label.relevant:
            self.status.content = "the policy is right to care: no variants of it"
        else:
            fine = self.space.describe(self.change.slot, self.change.concept, label.acceptable)
            self.status.content = f"variants may take: {fine}"
        for v, box in self.boxes.items():
            box.visible = ti
            if ti:
                box.value = v in label.acceptable
        if self.preset is not None:
            self._acceptable = label.acceptable if ti else self.values
            left_out = tuple(v for v in self.values if v not in set(self._acceptable))
            for handle in (self.preset, self.leave_out.handle, self.put_back.handle):
                handle.visible = ti
            # what is offered first: a dropdown may take its first option at once
            self._leave_offered = (NOT_CHOSEN, *self._acceptable)
            self._back_offered = (NOT_CHOSEN, *left_out)
            self.leave_out.handle.options = self._leave_offered
            self.leave_out.set(NOT_CHOSEN)
            self.put_back.handle.options = self._back_offered
            self.put_back.set(NOT_CHOSEN)


class FeedbackSection:
    """All mark controls of the selected edit, inside `folder`."""

    def __init__(self, client: viser.ClientHandle, state: LoopState, warn) -> None:
        self.client, self.state, self.warn = client, state, warn
        self.folder = client.gui.add_folder("4 · Feedback", visible=False)
        with self.folder:
            self.intro = client.gui.add_markdown("")
        self.controls: list[MarkControls] = []
        self._holder = None
        self._edit_key: tuple | None = None

    def refresh(self, view: View) -> None:
        run = view.record
        show = run is not None and view.stage in ("feedback", "adapted")
        self.folder.visible = show
        if not show:
            self._edit_key = None
            return
        edit = run.edit
        key = (id(run.task), str(edit))
        if key != self._edit_key:
            self._edit_key = key
            self._rebuild(view.world, edit)
        for c in self.controls:
            c.sync(run.label(*c.key))

    def _rebuild(self, world, edit) -> None:
        if self._holder is not None:
            self._holder.remove()
        self.controls = []
        if edit is None:
            self.intro.content = (
                "There is no edited concept to mark: the search found no counterfactual. "
                "Finetuning uses the demonstration alone."
            )
            self._holder = None
            return
        self.intro.content = (
            "For what you want, is each edited concept **task-irrelevant** (the policy should "
            "ignore it: it is shown variants of your demonstration with other looks you accept) "
            "or **task-relevant** (the policy is right to care)?"
        )
        gui = self.client.gui
        with self.folder:
            self._holder = gui.add_folder("edited concepts")
            with self._holder:
                for ch in edit.ordered:
                    self.controls.append(
                        MarkControls(self.client, self.state, ch, world.space, self.warn)
                    )
