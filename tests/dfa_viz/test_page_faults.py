"""Faults of the feedback page, run for real: two tabs pressing the same buttons at the same
moment, SIGTERM in the middle of a finetune and the resume after it, and control values the
page never offered sent over its own WebSocket.

The tabs are PageWire clients (page_wire.py): viser's protocol as the browser speaks it, with
the page's Origin; the server is `start` in this process, or `dfa serve` as a child process.
Every wait is for what the page shows; its ceiling only ends a hang.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from page_wire import CEILING_S, PageWire, free_port, session_events

from dfa_viz.app.feedback import TI, TR
from dfa_viz.app.page import ASK_EXPERT, FINETUNE, NEXT_TASK
from dfa_viz.configs import AdaptConfig, Finetuning
from sim.core import UserError

QUICK = AdaptConfig(budget=5, finetuning=Finetuning(steps=20))


@pytest.fixture
def served(tmp_path):
    """The page served in this process on a new session: (app, session folder)."""
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    state = open_state(session=tmp_path / "s", out=tmp_path / "rec", adapt=QUICK)
    app = start(port=free_port(), state=state)
    yield app, tmp_path / "s"
    app.stop()


def _to_feedback(tab: PageWire) -> None:
    """Load the default task, judge it failed, let the expert demonstrate; until the marks."""
    tab.click("Load task")
    tab.click("Failed")
    tab.click(ASK_EXPERT)
    tab.wait(lambda: tab.find(TI, "Button"), "the feedback controls", CEILING_S)


# -- two tabs racing one session ------------------------------------------------------------------
def _at_once(tabs: list[PageWire], label: str, presses: int = 3) -> None:
    """Every tab presses `label` `presses` times, all starting at the same moment."""
    uuids = [tab.wait_enabled(label, CEILING_S) for tab in tabs]
    start = threading.Barrier(len(tabs))

    def press(tab: PageWire, uuid: str) -> None:
        start.wait()
        for _ in range(presses):
            tab.update(uuid, value=True)

    threads = [threading.Thread(target=press, args=pair) for pair in zip(tabs, uuids, strict=True)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


def _same_page(a: PageWire, b: PageWire) -> None:
    """Until both tabs show the same words and the same task controls."""

    def same() -> bool:
        controls = [(t.value("world"), t.value("shift"), t.value("seed")) for t in (a, b)]
        return a.text() == b.text() and controls[0] == controls[1]

    a.wait(same, "the same page in both tabs", CEILING_S)


@pytest.mark.slow
def test_two_tabs_pressing_the_same_buttons_at_once_make_one_event_each(served, capfd, tmp_path):
    from dfa_viz.app.server import open_state

    app, folder = served
    a, b = PageWire(app.url), PageWire(app.url)
    tabs = [a, b]
    try:
        _at_once(tabs, "Load task")
        _at_once(tabs, "Failed")
        _at_once(tabs, ASK_EXPERT)
        for tab in tabs:
            tab.wait(lambda t=tab: t.find(TI, "Button"), "the feedback controls", CEILING_S)
        _at_once(tabs, TI)
        _at_once(tabs, FINETUNE)
        for tab in tabs:
            tab.wait_enabled(NEXT_TASK, CEILING_S)
        _same_page(a, b)
        live = app.state.record
        adapted = tmp_path / "adapted"
        shutil.copytree(folder, adapted)  # the session as it stands, to replay apart
        _at_once(tabs, NEXT_TASK)
        for tab in tabs:
            tab.wait_enabled("Failed", CEILING_S)
        _same_page(a, b)
    finally:
        a.close()
        b.close()

    kinds = [e["type"] for e in session_events(folder)]
    assert kinds == [
        "session",
        *("task", "judgement", "demonstration", "search", "mark", "finetune"),
        "task",
    ]
    assert [e["seed"] for e in session_events(folder) if e["type"] == "task"] == [0, 1]
    # one job each: one demonstration, one finetuned rollout, one checkpoint
    names = sorted(p.name for p in folder.iterdir())
    assert [n for n in names if n.startswith("demo-")] == [session_events(folder)[3]["file"]]
    assert [n for n in names if n.startswith("finetuned-")] == [
        session_events(folder)[6]["rollout_file"]
    ]
    assert [n for n in names if n.startswith("policy-")] == [
        session_events(folder)[6]["policy_dir"]
    ]
    # every press that came second was refused in one line ("not now", or "not offered now"
    # for a button already disabled), and nothing else was said
    pressed = ("Load task", "Failed", ASK_EXPERT, TI, FINETUNE, NEXT_TASK)
    for note in a.notes + b.notes:
        late = re.fullmatch(r"Refused: (.+) is not offered now", note)
        assert note.startswith("Not now: ") or (late and late.group(1) in pressed), note
        assert "\n" not in note, note
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err, (out + err)[-3000:]

    again = open_state(session=adapted, out=tmp_path / "rec2")  # replay rebuilds the same
    try:
        run = again.record
        assert again.snapshot().stage == "adapted"
        assert run.task == live.task and run.demo.equals(live.demo)
        assert run.feedback == live.feedback
        assert run.adaptation.rollout.equals(live.adaptation.rollout)
        assert run.adaptation.losses == pytest.approx(live.adaptation.losses, abs=1e-6)
        assert run.evaluation == live.evaluation
    finally:
        again.close()


@pytest.mark.slow
def test_a_late_press_of_a_step_that_is_over_is_not_taken_for_the_next(served):
    """A press names no label: a second "Continue: make variants and finetune" arriving after
    the finetune ended must not be taken for "Continue: another task", which the next-step
    button now offers."""
    app, folder = served
    tab = PageWire(app.url)
    try:
        tab.click("Load task")
        tab.click("Failed")
        expert = tab.wait_enabled(ASK_EXPERT, CEILING_S)
        tab.update(expert, value=True)
        tab.wait(lambda: tab.find(TI, "Button"), "the feedback controls", CEILING_S)
        tab.click(TI)
        finetune = tab.wait_enabled(FINETUNE, CEILING_S)
        tab.update(finetune, value=True)
        tab.wait_enabled(NEXT_TASK, CEILING_S)
        for late, label in ((expert, ASK_EXPERT), (finetune, FINETUNE)):
            n = len(tab.notes)
            tab.update(late, value=True)
            tab.wait(lambda n=n: len(tab.notes) > n, f"the late {label!r} refused", CEILING_S)
            assert tab.notes[-1] == f"Refused: {label} is not offered now"
        assert tab.enabled(NEXT_TASK)
    finally:
        tab.close()
    kinds = [e["type"] for e in session_events(folder)]
    assert kinds == ["session", "task", "judgement", "demonstration", "search", "mark", "finetune"]
    assert app.state.jobs.current is None


# -- SIGTERM during a finetune, then resume ---------------------------------------------------
class Serve:
    """`dfa serve ARGS` as a child process, its output kept, and a tab on its page."""

    def __init__(self, *args: str, cwd: Path) -> None:
        self.lines: list[str] = []
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "dfa_viz.cli", "serve", *args, "--port", str(free_port())],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self._seen = threading.Condition()
        self._drainer = threading.Thread(target=self._drain, daemon=True)
        self._drainer.start()
        with self._seen:
            self._seen.wait_for(lambda: self._url() or self.proc.poll() is not None, CEILING_S)
        assert self._url(), "".join(self.lines)
        self.tab = PageWire(self._url())

    def _drain(self) -> None:
        for line in self.proc.stdout:
            with self._seen:
                self.lines.append(line)
                self._seen.notify_all()

    def _url(self) -> str:
        m = re.search(r"the page is at (http://127\.0\.0\.1:\d+)", "".join(self.lines))
        return m.group(1) if m else ""

    def terminate(self) -> tuple[int, str]:
        """SIGTERM; the exit status and everything it printed."""
        self.proc.send_signal(signal.SIGTERM)
        code = self.proc.wait(timeout=CEILING_S)
        self._drainer.join(timeout=CEILING_S)  # its output, to the end
        self.proc.stdout.close()
        self.tab.close()
        return code, "".join(self.lines)

    def kill(self) -> None:
        """End it if a failed test left it running."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
            self._drainer.join()
            self.proc.stdout.close()
            self.tab.close()


@pytest.mark.slow
def test_sigterm_during_a_page_finetune_stops_cleanly_and_resumes(tmp_path):
    folder = tmp_path / "session"
    common = ("--world", "nav2d", "--session", str(folder), "--out", str(tmp_path / "rec"))
    # a finetune of 100,000 steps: it is surely running when the signal comes
    first = Serve(*common, "--budget", "3", "--steps", "100000", "--n-eval", "2", cwd=tmp_path)
    try:
        tab = first.tab
        _to_feedback(tab)
        tab.click(TI)
        tab.click(FINETUNE)
        tab.wait(lambda: "finetuning: step" in tab.text(), "the finetune under way", CEILING_S)
        code, out = first.terminate()
    finally:
        first.kill()

    assert code == 0, out
    assert "Traceback" not in out, out
    notes = [x for x in out.splitlines() if x.startswith("dfa serve:")]
    assert notes[-1] == f"dfa serve: stopped; the session is saved in {folder}", out
    # nothing of the cut finetune was written: no event, no rollout, no checkpoint
    log = session_events(folder)
    assert [e["type"] for e in log][-1] == "mark"
    assert not [p for p in folder.iterdir() if p.name.startswith(("finetuned-", "policy-"))]

    # what a kill in the middle of saving would leave: a checkpoint folder without its
    # weights and a cut rollout file, under the very names the next finetune would take
    n = len(log)
    (folder / f"policy-{n:04d}").mkdir()
    (folder / f"policy-{n:04d}" / "config.json").write_text('{"weights_sha256": "0"}\n')
    (folder / f"finetuned-{n:04d}.npz").write_bytes(b"PK\x03\x04 cut short")
    leftovers = {p.name for p in folder.iterdir()}

    second = Serve(*common, "--budget", "3", "--steps", "20", "--n-eval", "2", cwd=tmp_path)
    try:
        tab = second.tab
        tab.wait_enabled(FINETUNE, CEILING_S)  # the page offers the finetune again
        assert "variants may take: present or absent" in tab.text()  # the mark is kept
        tab.click(FINETUNE)
        tab.wait_enabled(NEXT_TASK, CEILING_S)
        assert "fresh tasks with the shift" in tab.text()
        code, out = second.terminate()
    finally:
        second.kill()
    assert code == 0 and "Traceback" not in out, out

    done = session_events(folder)[-1]
    assert done["type"] == "finetune"
    assert done["policy_dir"] not in leftovers and done["rollout_file"] not in leftovers
    assert {p.name for p in (folder / done["policy_dir"]).iterdir()} == {
        "model.safetensors",
        "config.json",
    }
    # the half-written files are left as they were and never read: the log replays
    from dfa_viz.app.server import open_state

    again = open_state(session=folder, out=tmp_path / "rec")
    try:
        assert again.snapshot().stage == "adapted"
        assert again.record.adaptation.rollout.success in (True, False)
    finally:
        again.close()


# -- forged control values ------------------------------------------------------------------------
def _refused(tab: PageWire, label: str, kind: str, value) -> str:
    """Send `value` for the control `label` (shown or not) as a forged message; the one line
    the tab is told."""
    uuids = tab.find(label, kind, shown=False)
    assert len(uuids) == 1, (label, kind)
    n = len(tab.notes)
    tab.update(uuids[0], value=value)
    tab.wait(lambda: len(tab.notes) > n, f"the refusal of {label} = {value!r}", CEILING_S)
    assert len(tab.notes) == n + 1, tab.notes[n:]
    return tab.notes[-1]


def test_forged_control_values_are_refused_in_one_line_and_never_acted_on(served, capfd):
    app, folder = served
    tab, other = PageWire(app.url), PageWire(app.url)
    try:
        for t in (tab, other):
            t.wait_enabled("Load task")
        for label, kind, value in [
            ("world", "Dropdown", "minigrid:MiniGrid-Empty-5x5-v0"),  # registered, not offered
            ("world", "Dropdown", "mars"),
            ("shift", "Dropdown", "sweep"),  # a shift only the Sweep tab's failures have
            ("shift", "Dropdown", "nonsense\nwith a second line"),
            ("seed", "Number", -1),
            ("seed", "Number", 2**40),
            ("tasks", "Number", 10**6),  # the Sweep tab's number of training tasks
            ("tasks", "Number", 0),
            ("speed", "Dropdown", "1000×"),
            ("saliency", "Dropdown", "everything"),
            ("step", "Slider", 10**6),
            ("step", "Slider", -3),
            ("minimal edit", "Dropdown", "1. goal.colour: red → blue"),  # hidden: no edit yet
        ]:
            note = _refused(tab, label, kind, value)
            assert note.startswith(f"Refused: {label} ") and "\n" not in note, note
        assert other.notes == []  # only the tab that sent them is told

        # refused before viser reads them (one line each, on the server): a control update
        # that sets anything but the value, a value no control takes, a frame that is not a
        # message; and a plain value of the wrong type, which viser's own cast refuses
        world, shift, seed = (tab.one(x) for x in ("world", "shift", "seed"))
        tab.update(world, options=["nav2d", "mars"])
        tab.update(shift, update_cb=0)
        tab.update(seed, value=float("nan"))
        tab.send({"type": "NoSuchMessage"})
        tab.ws.send(b"\xc1 not msgpack")
        tab.update(seed, value="abc")
        # the tab's controls work on as before: an offered value is taken without a word
        tab.update(shift, value="object_ti")
        tab.wait(
            lambda: any(p.task.shift.value == "object_ti" for p in app.pages.values()),
            "the offered shift taken",
            CEILING_S,
        )
        tab.update(shift, value="distractor_ti")
        # forged values and Load pressed at once: the task is the one the page offered
        n = len(tab.notes)
        tab.update(world, value="mars")
        tab.update(seed, value=-7)
        tab.click("Load task")
        tab.wait(lambda: len(tab.notes) == n + 2, "the two refusals", CEILING_S)
        tab.wait_enabled("Failed", CEILING_S)
        assert [e["type"] for e in session_events(folder)] == ["session", "task"]
        task = session_events(folder)[1]
        assert (task["world"], task["shift"], task["seed"]) == ("nav2d", "distractor_ti", 0)
        assert app.state.sweep is None  # no sweep ran
        _same_page(tab, other)  # and neither tab shows a forged value

        # at the feedback: a press on a control that is not offered now, a hidden checkbox
        tab.click("Failed")
        tab.click(ASK_EXPERT)
        tab.wait(lambda: tab.find(TR, "Button"), "the feedback controls", CEILING_S)
        note = _refused(tab, "Succeeded", "Button", True)  # judged already: disabled
        assert note == "Refused: Succeeded is not offered now"
        tab.click(TR)
        tab.wait(lambda: "right to care" in tab.text(), "the TR mark", CEILING_S)
        (edited,) = app.state.record.edit.ordered
        values = app.state.snapshot().world.space.values(edited.slot, edited.concept)
        note = _refused(tab, values[-1], "Checkbox", False)  # shown only while marked TI
        assert note == f"Refused: {values[-1]} is not offered now"
        tab.click(TI)
        tab.wait(lambda: "variants may take" in tab.text(), "the TI mark", CEILING_S)
        mark = session_events(folder)[-1]
        assert mark["type"] == "mark" and mark["acceptable"] == list(values)
        # the page's own changes (new ties, new options) are never taken for a tab's
        assert sum("minimal edit" in note for note in tab.notes) == 1
        assert other.notes == []
    finally:
        tab.close()
        other.close()
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err, (out + err)[-3000:]
    refusals = [x for x in out.splitlines() if "refused a message" in x]
    for why in ("sets options", "sets update_cb", "finite number", "KeyError", "Decode", "'abc'"):
        assert sum(why in x for x in refusals) == 1, (why, refusals)


def test_stale_or_forged_actions_are_refused_before_they_are_written(served, tmp_path):
    """Through the state itself (what any tab's press comes to): values the page does not
    offer, a mark of a concept the edit does not change, a tie that does not exist. None is
    written, so the session still resumes."""
    from dfa_viz.app.server import open_state, wait_idle

    app, folder = served
    state = app.state
    for call, words in [
        (lambda: state.pick("minigrid:MiniGrid-Empty-5x5-v0", "object_ti", 0), "no world"),
        (lambda: state.pick("nav2d", "sweep", 0), "no shift 'sweep'"),
        (lambda: state.pick("nav2d", "object_ti", -1), "seed must be"),
        (lambda: state.run_sweep("nav2d", 10**6), "1 to 500 tasks"),
        (lambda: state.run_sweep("mars", 5), "no world 'mars'"),
    ]:
        with pytest.raises(UserError, match=words):
            call()
    assert state.jobs.current is None and state.sweep is None
    state.pick("nav2d", "distractor_ti", 0)
    wait_idle(state, timeout_s=CEILING_S)
    state.judge(True)
    state.demonstrate(expert=True)
    wait_idle(state, timeout_s=CEILING_S)
    log = (folder / "session.jsonl").read_bytes()
    with pytest.raises(UserError, match="not an edited concept"):
        state.mark("goal", "colour", relevant=True, acceptable=())
    with pytest.raises(UserError, match="has no"):
        state.mark("distractor", "presence", relevant=False, acceptable=("sideways",))
    with pytest.raises(UserError, match="tie 7 does not exist"):
        state.select_tie(7)
    assert (folder / "session.jsonl").read_bytes() == log
    app.stop()
    again = open_state(session=folder, out=tmp_path / "rec")
    try:
        assert again.snapshot().stage == "feedback"
    finally:
        again.close()
