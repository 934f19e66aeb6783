"""The feedback controls of one tab: for each concept the selected edit changes, a TI / TR
choice and, for TI, which instantiations are acceptable. Rebuilt when the edit changes;
synced from the shared state when another tab marks something."""

from __future__ import annotations

import viser

from dfa_viz.app.state import LoopState
from dfa_viz.app.view import View
from sim.core import Change, Label, UserError

TI = "Task-irrelevant (TI)"
TR = "Task-relevant (TR)"
MAX_CHECKBOXES = 12  # above this many instantiations, a comma-separated text field


class MarkControls:
    """The controls for one edited concept."""

    def __init__(self, gui, state: LoopState, change: Change, values: tuple[str, ...], warn):
        self.state, self.change, self.values, self.warn = state, change, values, warn
        self.key = (change.slot, change.concept)
        name = f"{change.slot}.{change.concept}"
        gui.add_markdown(f"**{name}**: {change.old} → {change.new}")
        self.choice = gui.add_button_group(name, (TI, TR))
        self.status = gui.add_markdown("not marked yet")
        self.boxes: dict[str, viser.GuiCheckboxHandle] = {}
        self.text = None
        if len(values) <= MAX_CHECKBOXES:
            for v in values:
                box = gui.add_checkbox(f"{v}", True, hint=f"{name} = {v} is fine", visible=False)
                box.on_update(self._on_box)
                self.boxes[v] = box
        else:
            self.text = gui.add_text(
                f"acceptable {change.concept}s",
                "",
                hint="comma-separated; empty = all",
                visible=False,
            )
            self.text.on_update(self._on_box)
        self.choice.on_click(self._on_choice)

    def acceptable(self) -> tuple[str, ...]:
        if self.text is not None:
            raw = [v.strip() for v in self.text.value.split(",") if v.strip()]
            bad = [v for v in raw if v not in self.values]
            if bad:
                raise UserError(
                    f"unknown {self.change.concept} {bad}; accepted: {', '.join(self.values)}"
                )
            return tuple(raw) or self.values
        return tuple(v for v, box in self.boxes.items() if box.value)

    def _on_choice(self, event) -> None:
        relevant = event.target.value == TR
        try:
            acceptable = () if relevant else self.acceptable()
            if not relevant and not acceptable:
                acceptable = self.values
            self.state.mark(*self.key, relevant=relevant, acceptable=acceptable)
        except UserError as e:
            self.warn(str(e))

    def _on_box(self, event) -> None:
        if event.client is None:
            return  # set from the shared state, not by this user
        try:
            acceptable = self.acceptable()
            if not acceptable:
                self.warn("keep at least one acceptable instantiation, or mark the concept TR")
                self.sync(self.state.snapshot().record.label(*self.key))
                return
            self.state.mark(*self.key, relevant=False, acceptable=acceptable)
        except UserError as e:
            self.warn(str(e))

    def sync(self, label: Label | None) -> None:
        """Show the shared mark (set by this tab or another)."""
        ti = label is not None and not label.relevant
        if label is None:
            self.status.content = "not marked yet"
        elif label.relevant:
            self.status.content = "✔ **TR** — the policy is right to care; no augmentation"
        else:
            self.status.content = "✔ **TI** — acceptable: " + ", ".join(label.acceptable)
        for v, box in self.boxes.items():
            box.visible = ti
            if ti:
                box.value = v in label.acceptable
        if self.text is not None:
            self.text.visible = ti
            if ti:
                acc = label.acceptable
                self.text.value = "" if set(acc) == set(self.values) else ", ".join(acc)


class FeedbackSection:
    """All mark controls of the selected edit, inside `folder`."""

    def __init__(self, client: viser.ClientHandle, state: LoopState, warn) -> None:
        self.client, self.state, self.warn = client, state, warn
        self.folder = client.gui.add_folder("5 · Feedback", visible=False)
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
            "ignore it: augment over the instantiations you accept) or **task-relevant**?"
        )
        gui = self.client.gui
        with self.folder:
            self._holder = gui.add_folder("edited concepts")
            with self._holder:
                for ch in edit.ordered:
                    values = world.space.values(ch.slot, ch.concept)
                    self.controls.append(MarkControls(gui, self.state, ch, values, self.warn))
