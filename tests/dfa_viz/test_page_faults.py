"""Faults of the feedback page, run for real: two tabs pressing the same buttons at the same
moment, and SIGTERM in the middle of a finetune and the resume after it (control values the
page never offered: test_page_forgery.py).

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
from page_wire import CEILING_S, PageWire, free_port, same_page, session_events

from dfa_viz.app.feedback import TI
from dfa_viz.app.page import ASK_EXPERT, FINETUNE, NEXT_TASK


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
        same_page(a, b)
        live = app.state.record
        adapted = tmp_path / "adapted"
        shutil.copytree(folder, adapted)  # the session as it stands, to replay apart
        _at_once(tabs, NEXT_TASK)
        for tab in tabs:
            tab.wait_enabled("Failed", CEILING_S)
        same_page(a, b)
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
        assert re.search(r"Paired, of \d+ distinct, \d+ newly solved", tab.text())
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
