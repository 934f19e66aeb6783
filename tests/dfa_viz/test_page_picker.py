"""The page's world picker lists a world typed by name, in every tab, and refuses in one line
what no registered prefix builds; the next step says why it waits."""

from __future__ import annotations

import pytest
from page_wire import CEILING_S, PageWire, free_port

from dfa_viz.app.feedback import TI
from dfa_viz.app.page import ASK_EXPERT, FINETUNE
from dfa_viz.configs import AdaptConfig, Finetuning

QUICK = AdaptConfig(budget=5, finetuning=Finetuning(steps=20))

EMPTY = "minigrid:MiniGrid-Empty-5x5-v0"


@pytest.fixture
def served(tmp_path):
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    state = open_state(session=tmp_path / "s", out=tmp_path / "rec", adapt=QUICK)
    app = start(port=free_port(), state=state)
    yield app
    app.stop()


def _type_world(tab: PageWire, name: str) -> None:
    tab.update(tab.one("another world", "Text"), value=name)  # taken before the press
    tab.click("List this world")


def test_a_typed_world_is_listed_in_every_tab_and_bad_names_get_one_line(served):
    tab, other = PageWire(served.url), PageWire(served.url)
    try:
        for t in (tab, other):
            t.wait_enabled("Load task")
        assert EMPTY not in tab.gui[tab.one("world", "Dropdown")]["options"]
        _type_world(tab, EMPTY)
        for t in (tab, other):
            t.wait(
                lambda t=t: EMPTY in t.gui[t.one("world", "Dropdown")]["options"],
                "the typed world listed",
                CEILING_S,
            )
        tab.wait(lambda: tab.value("world") == EMPTY, "the typed world chosen", CEILING_S)
        shifts = tab.gui[tab.one("shift", "Dropdown")]["options"]
        assert list(shifts) == ["distractor_ti", "other"]  # the MiniGrid world's own
        for name, said in [
            ("mars", "no world 'mars' here; accepted: minigrid:<name>"),
            ("os:system", "no world 'os:system' here"),  # a module is never imported
            ("minigrid:NoSuchEnv-v0", "NoSuchEnv-v0"),
        ]:
            n = len(tab.notes)
            _type_world(tab, name)
            tab.wait(lambda n=n: len(tab.notes) > n, f"the refusal of {name}", CEILING_S)
            assert said in tab.notes[-1] and "\n" not in tab.notes[-1], tab.notes[-1]
            assert name not in tab.gui[tab.one("world", "Dropdown")]["options"]
    finally:
        tab.close()
        other.close()


def test_the_next_step_says_why_it_waits_until_it_may_be_pressed(served):
    tab = PageWire(served.url)
    try:
        tab.click("Load task")
        tab.click("Failed")
        tab.click(ASK_EXPERT)
        tab.wait(lambda: tab.find(TI, "Button"), "the feedback controls", CEILING_S)
        reason = "*Mark distractor.presence first.*"  # beside the waiting button
        tab.wait(lambda: reason in tab.text(), "why finetuning waits", CEILING_S)
        assert not tab.enabled(FINETUNE)
        tab.click(TI)
        tab.wait(lambda: tab.enabled(FINETUNE), "finetuning offered", CEILING_S)
        tab.wait(lambda: "first." not in tab.text(), "no stale reason", CEILING_S)
    finally:
        tab.close()
