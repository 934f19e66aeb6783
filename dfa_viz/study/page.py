"""The study page of one browser tab: a participant code, the familiarisation, the questions.

Each question shows what the robot did on a frozen task (and, by the question's condition,
what it does once the counterfactual's change is made, side by side; the saliency heat over
its frames; or nothing more), then asks what made it fail (the concepts the scene shows at
their values, or "the cause is not among these") and whether that should matter for what
the participant asked for (not asked after "not among these": no cause named, nothing said
to matter). The question fills the main panel, docked left (so viser's developer panel stays
folded away); the answer a panel docked right, its Submit button in view at any height.
Keys: 1-9 tick a concept, 0 the "not among these" answer, Y / N the second question, Enter
goes on. An answer is on disk (answers.Store) before the next
question is drawn; nothing the page is sent says what the right answer is (the page never
reads truth.json).
"""

from __future__ import annotations

import contextlib
import threading
import time
import uuid
from collections.abc import Callable

import numpy as np
import viser

from dfa_viz.app.frames import frame_at, strip
from dfa_viz.overlay import blend
from dfa_viz.study.answers import Answer, Store
from dfa_viz.study.freeze import FrozenTask
from dfa_viz.study.intro import COLOURS
from dfa_viz.study.protocol import Protocol, Question
from sim.core import UserError

PANEL_PX = 800  # the question's panel, docked left over the (unused) 3D view
ANSWER_PX = 440  # the answer's panel, docked right: the Submit button in view at 1280x720
ASK_MATTERS = "Should that matter for what you asked for?"
MATTERS = ("(press Y or N)", "Yes, it matters", "No, it does not matter")
NONE_LABEL = "0 · The cause is not among these"
KIND_TEXT = {
    "object": "**One thing looks different** from the scenes the robot learnt on: the {looks} "
    "of something it knows.",
    "distractor": "**Something new is in the scene**, something that was not there when the "
    "robot learnt.",
    "other": "**Something else changed** that is none of the looks listed, for instance where "
    "things are.",
}


class StudyPage:
    """The GUI of one tab; `join` is the only way in, so every tab is its own participant."""

    def __init__(self, client: viser.ClientHandle, study) -> None:
        self.client, self.study = client, study
        self.session = uuid.uuid4().hex[:12]  # this tab's connection: every answer names it
        self.store: Store = study.store
        self.protocol: Protocol = study.protocol
        self.pid: str | None = None
        self.questions: list[Question] = []
        self.position = 0
        self.shown_at = 0.0
        self._lock = threading.RLock()
        self._handles: list = []
        self._holder = None
        self._answer = None  # the answer's panel, while a question is shown
        # the study's GUI is the main panel's own: viser then folds its developer panel (the
        # server's address, Save Canvas, Dev Settings, the scene tree) away behind an icon
        client.gui.main_panel.dock_left()
        client.gui.main_panel.set_width(PANEL_PX)
        self.welcome()

    # -- screens ------------------------------------------------------------------------------
    def _screen(self, title: str):
        for h in self._handles:
            h.remove()
        self._handles = []
        if self._holder is not None:
            self._holder.remove()
        if self._answer is not None:
            self._answer.remove()
            self._answer = None
        self._holder = self.client.gui.add_folder(title)
        return self._holder

    def _key(self, hotkey: str, label: str, fn: Callable[[], None]) -> None:
        cmd = self.client.gui.add_command(label, hotkey=hotkey)
        cmd.on_trigger(lambda _: self._guard(fn))
        self._handles.append(cmd)

    def _guard(self, fn: Callable[[], None]) -> None:
        with self._lock:
            try:
                fn()
            except UserError as e:
                self.client.add_notification("Not yet", str(e), color="red", auto_close_seconds=6)

    def welcome(self) -> None:
        gui = self.client.gui
        with self._screen("Welcome"):
            gui.add_markdown(
                "Thank you for taking part. You will see a robot fail at a task and say what "
                "you think made it fail.\n\nType the **participant code** you were given "
                "(such as P07-K7QX) and press Start."
            )
            code = gui.add_text("Participant code", initial_value="")
            start = gui.add_button("Start")
        start.on_click(lambda _: self._guard(lambda: self.join(code.value)))

    def join(self, pid: str) -> None:
        """Start or resume participant `pid` (one tab per participant at a time)."""
        pid = self.study.claim(pid, self)
        _, questions, answers = self.store.join(pid)
        self.pid, self.questions, self.position = pid, questions, len(answers)
        if self.position >= len(questions):
            self.finished()
        elif self.position:
            self.ask()
        else:
            self.intro(0)

    def intro(self, i: int) -> None:
        conditions = {q.condition for q in self.questions}
        screens = intro_screens(self.protocol, conditions, self.study.intro)
        title, text, picture = screens[i]
        gui = self.client.gui
        last = i == len(screens) - 1
        go = self.ask if last else (lambda: self.intro(i + 1))
        holder = self._screen(f"Introduction {i + 1} of {len(screens)}: {title}")
        self._key("enter", "Next", go)  # before the picture: Enter works as soon as it shows
        with holder:
            gui.add_markdown(text)
            nxt = gui.add_button("Start the questions (Enter)" if last else "Next (Enter)")
            nxt.on_click(lambda _: self._guard(go))  # before the picture: no click is lost
            if picture is not None:
                gui.add_image(picture, label=title, format="png")

    def finished(self) -> None:
        with self._screen("Done"):
            self.client.gui.add_markdown(
                "**Thank you!** Every answer is saved. You can close this window."
            )

    # -- a question ---------------------------------------------------------------------------
    def ask(self) -> None:
        """Draw the participant's next unanswered question."""
        q = self.questions[self.position]
        task = self.study.task(q)
        gui = self.client.gui
        n = len(self.questions)
        self.task, self.question = task, q
        with self._screen(f"Question {self.position + 1} of {n}"):
            gui.add_markdown(f"**What you asked for:** {task.instruction}.\n\nThe robot failed.")
            self.image = gui.add_image(self.frames(task, q.condition, 0), label="", format="png")
            last = max(len(task.failed.observations), self._cf_len(task)) - 1
            slider = gui.add_slider("step", min=0, max=max(last, 1), step=1, initial_value=0)
            if q.condition in ("counterfactual", "both"):
                gui.add_markdown(
                    "**What changed** (after this change the robot does what it was shown):\n\n"
                    + task.changed
                    if task.changed
                    else "**No change of the looks** makes the robot do what it was shown."
                )
        # the answer in a panel of its own, docked right: in view whatever the window's height
        self._answer = gui.add_panel()
        with self._answer.add_tab("Your answer"):
            gui.add_markdown("**What made the robot fail?** Tick all that apply (keys 1–9).")
            self.boxes = [
                gui.add_checkbox(f"{k + 1} · {c['label']}", initial_value=False)
                for k, c in enumerate(task.choices)
            ]
            self.none = gui.add_checkbox(NONE_LABEL, initial_value=False)
            self.matters = gui.add_dropdown(ASK_MATTERS, MATTERS, initial_value=MATTERS[0])
            submit = gui.add_button("Submit answer (Enter)")
        self._answer.dock_right()
        self._answer.set_width(ANSWER_PX)
        self.none.on_update(lambda _: setattr(self.matters, "disabled", bool(self.none.value)))
        slider.on_update(lambda _: self._show_step(int(slider.value)))
        submit.on_click(lambda _: self._guard(self.submit))
        for k, box in enumerate(self.boxes[:9]):
            self._key(str(k + 1), f"Tick {k + 1}", self._toggler(box))
        self._key("0", "Not among these", self._toggler(self.none))
        self._key("Y", "Yes, it matters", lambda: setattr(self.matters, "value", MATTERS[1]))
        self._key("N", "No, it does not", lambda: setattr(self.matters, "value", MATTERS[2]))
        self._key("enter", "Submit", self.submit)
        self.shown_at = time.monotonic()

    @staticmethod
    def _toggler(box) -> Callable[[], None]:
        return lambda: setattr(box, "value", not box.value)

    @staticmethod
    def _cf_len(task: FrozenTask) -> int:
        return 0 if task.counterfactual is None else len(task.counterfactual.observations)

    def _show_step(self, step: int) -> None:
        with self._lock:
            self.image.image = self.frames(self.task, self.question.condition, step)

    @staticmethod
    def frames(task: FrozenTask, condition: str, step: int) -> np.ndarray:
        """The question's strip at `step`: uint8 (H, W, 3)."""
        frame = frame_at(task.failed, step)
        cols = [("what the robot did", frame, "", COLOURS[2])]
        if condition in ("saliency", "both"):
            heat = blend(frame, task.saliency[step]) if step < len(task.saliency) else frame
            cols.append(("where it looked", heat, "", COLOURS[2]))
        if condition in ("counterfactual", "both"):
            cf = frame_at(task.counterfactual, step)
            cols.append(("after one change", cf, "no change found", COLOURS[1]))
        return strip(cols, frame_shape=task.failed.observations.shape[1:])

    def submit(self) -> None:
        """Check the answer, write it durably, then draw the next question."""
        selected = tuple(
            c["key"] for c, b in zip(self.task.choices, self.boxes, strict=True) if b.value
        )
        none = bool(self.none.value)
        if none and selected:
            raise UserError("tick concepts or 'not among these', not both")
        if not none and not selected:
            raise UserError("tick what made it fail, or 'the cause is not among these' (0)")
        if self.matters.value == MATTERS[0] and not none:
            raise UserError("say whether it should matter for what you asked for (Y or N)")
        answer = Answer(
            position=self.position,
            task=self.task.id,
            selected=selected,
            none=none,
            matters=self.matters.value == MATTERS[1] and not none,
            duration_s=round(time.monotonic() - self.shown_at, 3),
            via="page",
            session=self.session,
        )
        self.store.answer(self.pid, answer)  # on disk before the page moves on
        self.position += 1
        if self.position >= len(self.questions):
            self.finished()
        else:
            self.ask()

    def close(self) -> None:
        with contextlib.suppress(Exception):  # the tab may be gone already
            for part in (self._holder, self._answer):
                if part is not None:
                    part.remove()
        if self.pid is not None:
            self.study.release(self.pid, self)


def intro_screens(
    protocol: Protocol, conds: set[str], pictures: Callable[[str], dict]
) -> list[tuple[str, str, np.ndarray | None]]:
    """(title, text, picture) of every familiarisation screen, in order, for a participant
    whose questions have the conditions `conds`: an explanation is introduced only to those it
    is shown to (between subjects). `pictures(world)`: its pictures (freeze.load_intro)."""
    out: list[tuple[str, str, np.ndarray | None]] = [
        (
            "How it works",
            "In every question the robot was asked to do something (**what you asked "
            "for**) in a new scene, and it failed. You say **what made it fail**, from the "
            "looks of the things in the scene, and whether that **should matter** for what "
            "you asked for. Take your time; there are no trick questions.",
            None,
        )
    ]
    for world, _ in protocol.tasks:
        pics = pictures(world)
        out.append(
            (
                f"The things in the scene ({world})",
                str(pics.get("description", ""))
                + " These are the looks the things can have; one of them, or none, made "
                "the robot fail.",
                pics["concepts"],
            )
        )
        looks = str(pics.get("looks", "colour or shape"))  # older studies: no "looks"
        for kind in protocol.kinds:
            text = KIND_TEXT[kind].format(looks=looks)
            out.append((f"What can change ({world})", text, pics[f"example_{kind}"]))
        if conds & {"counterfactual", "both"}:
            out.append(
                (
                    f"After one change ({world})",
                    "Some questions also show **what the robot does after one change**: "
                    "the smallest change of the looks in the scene after which the robot "
                    "does what it was shown. What changed is what the robot pays attention "
                    "to. When no such change exists, the cause is not among the looks.",
                    pics["counterfactual"],
                )
            )
    if conds & {"saliency", "both"}:
        out.append(
            (
                "Where it looked",
                "Some questions colour the robot's view: the redder and brighter a spot, "
                "the more it pushed the robot away from what it was shown.",
                None,
            )
        )
    return out
