"""`dfa study serve` in Chromium: three scripted participants, a crash mid-study, the analysis
of their answers, and no ground truth in anything the page is sent."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from conftest import UI, WAIT_S, ChildServer  # tests/browser/conftest.py
from playwright.sync_api import expect

from dfa_viz.study.codes import CODES
from dfa_viz.study.freeze import TRUTH, freeze
from dfa_viz.study.page import MATTERS
from dfa_viz.study.protocol import Protocol
from dfa_viz.study.report import write_analysis

pytestmark = pytest.mark.browser

PROTOCOL = Protocol(tasks=(("nav2d", 1),), conditions=("none", "counterfactual"), seed=0)
SECRETS = ("object_ti", "object_tr", "distractor_ti", "distractor_tr", "relevance", "task_seed")


VIEWPORT = {"width": 1280, "height": 900}  # where the participants answer


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("study") / "s"
    freeze(PROTOCOL, out)
    return out


class Participant:
    """A script that answers with known choices: right under the counterfactual, wrong
    without it; "it matters" on every TR task, "it does not" on TI."""

    def __init__(self, browser, url: str, pid: str, folder: Path, *, keyboard: bool, frames):
        self.pid, self.folder, self.keyboard = pid, folder, keyboard
        self.page = browser.new_page(viewport=VIEWPORT)
        self.page.set_default_timeout(WAIT_S * 1000)
        self.page.on("websocket", lambda ws: ws.on("framereceived", lambda f: frames.append(f)))
        self.page.goto(url)
        self.page.get_by_role("button", name="Start").wait_for()
        UI.in_view_at_every_size(self.page, self.page.get_by_role("button", name="Start"))
        self.page.set_viewport_size(VIEWPORT)
        for dev in ("Save Canvas", "Dev Settings"):  # viser's developer panel: folded away
            assert not self.page.get_by_role("button", name=dev).first.is_visible(), dev
        assert not self.page.get_by_text("Scene tree").first.is_visible()
        assert not self.page.locator("input[value^='ws://']").first.is_visible()
        UI.dismiss_notifications(self.page)
        self.page.get_by_role("textbox").first.fill(pid)
        self.page.get_by_role("button", name="Start").click()
        self.truth = json.loads((folder / TRUTH).read_text())

    def plan(self) -> list[dict]:
        lines = (self.folder / "answers" / f"{self.pid}.jsonl").read_text().splitlines()
        return json.loads(lines[0])["plan"]

    def answers_on_disk(self) -> int:
        lines = (self.folder / "answers" / f"{self.pid}.jsonl").read_text().splitlines()
        return len(lines) - 1

    def through_the_introduction(self) -> None:
        page = self.page
        page.get_by_text("Introduction 1 of").first.wait_for()
        n = int(
            page.get_by_text("Introduction 1 of").first.inner_text().split(" of ")[1].split(":")[0]
        )
        for i in range(1, n + 1):
            page.get_by_text(f"Introduction {i} of {n}").first.wait_for()
            page.get_by_role("button", name="(Enter)").wait_for()
            UI.in_view_at_every_size(page, page.get_by_role("button", name="(Enter)"))
            page.set_viewport_size(VIEWPORT)
            if self.keyboard:
                page.keyboard.press("Enter")
            else:
                page.get_by_role(
                    "button", name="Next (Enter)" if i < n else "Start the questions (Enter)"
                ).click()
        page.get_by_text("Question 1 of").first.wait_for()

    def choice(self, position: int) -> tuple[list[str], bool, bool]:
        """(concepts ticked, "not among these", it matters) for the plan's question."""
        q = self.plan()[position]
        index = json.loads((self.folder / "study.json").read_text())["tasks"]
        t = self.truth[index[f"{q['world']}/{q['kind']}/{q['index']}"][q["shift"]]]
        right = q["condition"] == "counterfactual"
        if t["kind"] == "other":
            return ([] if right else ["goal.colour"]), right, False
        return (list(t["required"]) if right else ["goal.colour"]), False, t["relevance"] == "TR"

    def answer(self, position: int, n: int) -> None:
        page = self.page
        page.get_by_text(f"Question {position + 1} of {n}").first.wait_for()
        view = self.view(position)
        keys = [c["key"] for c in view["choices"]]
        ticked, none, matters = self.choice(position)
        submit = page.get_by_role("button", name="Submit answer (Enter)")
        submit.wait_for()
        UI.in_view_at_every_size(page, submit)
        page.set_viewport_size(VIEWPORT)
        shown = page.content()
        assert ("What changed" in shown or "No change of the looks" in shown) == (
            self.plan()[position]["condition"] == "counterfactual"
        )  # the explanation only where the condition gives it
        if self.keyboard:
            page.locator("body").click(
                position={"x": 800, "y": 880}
            )  # the 3D view between the panels
            # The keys reach the page after the button, in the order they were registered:
            # Y / N (which only set the answer, so pressing again does no harm) until the page
            # shows its answer; that answer came after every key, Enter included.
            key, said = ("Y", MATTERS[1]) if matters else ("N", MATTERS[2])
            matters_box = page.locator("input[role='combobox']:visible").first
            if not none:  # after "not among these" the page does not ask
                UI.wait_until(
                    lambda: page.keyboard.press(key) or matters_box.input_value() == said,
                    f"the {key} key to answer {said!r}",
                )
            boxes = page.get_by_role("checkbox")
            for c in ticked:
                page.keyboard.press(str(keys.index(c) + 1))
                expect(boxes.nth(keys.index(c))).to_be_checked()
            if none:
                page.keyboard.press("0")
                expect(boxes.nth(len(keys))).to_be_checked()
            page.keyboard.press("Enter")
        else:
            boxes = page.get_by_role("checkbox")
            for c in ticked:
                boxes.nth(keys.index(c)).click()
            if none:  # "should that matter?" is then not asked: its box is disabled
                boxes.nth(len(keys)).click()
                expect(page.locator("input[role='combobox']:visible").first).to_be_disabled()
            else:
                choice = "Yes, it matters" if matters else "No, it does not matter"
                page.locator("input[role='combobox']:visible").first.click()
                page.get_by_role("option", name=choice).click()
            page.get_by_role("button", name="Submit answer (Enter)").click()
        nxt = f"Question {position + 2} of {n}" if position + 1 < n else "Thank you!"
        page.get_by_text(nxt).first.wait_for()
        assert self.answers_on_disk() == position + 1  # on disk before the page moved on

    def view(self, position: int) -> dict:
        q = self.plan()[position]
        index = json.loads((self.folder / "study.json").read_text())["tasks"]
        tid = index[f"{q['world']}/{q['kind']}/{q['index']}"][q["shift"]]
        return json.loads((self.folder / "tasks" / tid / "view.json").read_text())


def test_three_participants_a_crash_and_the_analysis(browser, study, study_check):
    n = len(PROTOCOL.slots)
    frames: list = []
    codes = (study / CODES).read_text().split()
    server = ChildServer(["study", "serve", str(study)])
    stray = Participant(browser, server.url, "P01", study, keyboard=False, frames=frames)
    stray.page.get_by_text("P01 is not a code of this study").first.wait_for()  # not issued
    stray.page.close()
    p1 = Participant(browser, server.url, codes[0], study, keyboard=True, frames=frames)
    p1.through_the_introduction()
    p1.answer(0, n)
    server.kill()  # a crash mid-study: the answer given is on disk, the next one was not
    assert p1.answers_on_disk() == 1
    p1.page.close()
    server = ChildServer(["study", "serve", str(study)])
    try:
        p1 = Participant(browser, server.url, codes[0], study, keyboard=True, frames=frames)
        p1.page.get_by_text(f"Question 2 of {n}").first.wait_for()  # resumed where it stopped
        # two more participants at once, by mouse, their questions interleaved
        p2 = Participant(browser, server.url, codes[1], study, keyboard=False, frames=frames)
        p3 = Participant(browser, server.url, codes[2], study, keyboard=False, frames=frames)
        twin = Participant(browser, server.url, codes[1], study, keyboard=False, frames=frames)
        twin.page.get_by_text("is open in another window").first.wait_for()  # one tab a code
        twin.page.close()
        p2.through_the_introduction()
        p3.through_the_introduction()
        for j in range(n):
            p2.answer(j, n)
            p3.answer(j, n)
            if j >= 1:
                p1.answer(j, n)
        dom = "".join(p.page.content() for p in (p1, p2, p3))
    finally:
        server.kill()
    assert frames, "no websocket traffic was seen"
    traffic = b"".join(f if isinstance(f, bytes) else f.encode() for f in frames)
    for secret in SECRETS:  # the ground truth never reaches the page
        assert secret.encode() not in traffic and secret not in dom, secret

    a = write_analysis(study)
    truth = json.loads((study / TRUTH).read_text())
    assert len(a.rows) == 3 * n
    for r in a.rows:
        assert r["correct"] == study_check.correct(
            truth[r["task"]], r["selected"].split(), bool(r["none"])
        )
        assert r["correct"] == (r["condition"] == "counterfactual") and float(r["duration_s"]) > 0
    for c in a.cells:
        assert c.accuracy == (1.0 if c.condition == "counterfactual" else 0.0)
    cf = sum(r["condition"] == "counterfactual" for r in a.rows)
    (chi,) = a.chi2
    stat, p = study_check.chi2(cf, 0, 0, 3 * n - cf)
    assert math.isclose(chi.chi2, stat) and math.isclose(chi.p, p)
    pairs = [(1.0, 0.0)] * 3  # every participant had one TR and one TI task
    assert a.pairs == 3 and math.isclose(
        a.wilcoxon_p, study_check.wilcoxon(*zip(*pairs, strict=True))
    )
    assert a.rejection == 1.0
