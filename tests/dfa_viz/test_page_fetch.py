"""The page on a closed-loop MuJoCo world (`dfa serve --world fetch:FetchPickAndPlace-v4`): the
failed rollout, the scripted demonstration and the search, answered in the world's terms, then
TI feedback and a finetuned policy, every step on disk in the session."""

from __future__ import annotations

import json

import pytest
from page_wire import CEILING_S, PageWire, free_port

from dfa_viz.app.feedback import TI
from dfa_viz.app.page import ASK_EXPERT, FINETUNE
from dfa_viz.configs import AdaptConfig, Finetuning

FETCH = "fetch:FetchPickAndPlace-v4"
QUICK = AdaptConfig(budget=3, finetuning=Finetuning(steps=10, n_eval=2))


@pytest.fixture
def served(tmp_path):
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    state = open_state(world=FETCH, session=tmp_path / "s", out=tmp_path / "rec", adapt=QUICK)
    app = start(port=free_port(), state=state)
    yield app, tmp_path / "s"
    app.stop()


def test_the_page_diagnoses_and_adapts_the_fetch_policy(served):
    app, session = served
    tab = PageWire(app.url)
    try:
        tab.wait_enabled("Load task", CEILING_S)
        assert tab.value("world") == FETCH
        tab.update(tab.one("shift", "Dropdown"), value="object_ti")
        tab.wait(
            lambda: any(p.task.shift.value == "object_ti" for p in app.pages.values()),
            "the shift taken",
            CEILING_S,
        )
        tab.click("Load task")  # seed 0: the table recoloured green
        tab.click("Failed")
        tab.click(ASK_EXPERT)
        tab.wait(lambda: tab.find(TI, "Button"), "the feedback controls", CEILING_S)
        text = tab.text()
        assert "The policy does the task you demonstrated" in text, text
        assert "| table | colour | green → **light grey** |" in text, text
        tab.click(TI)
        tab.wait(lambda: tab.enabled(FINETUNE), "finetuning offered", CEILING_S)
        tab.click(FINETUNE)
        tab.wait(lambda: "Adapted." in tab.text(), "the finetuned policy", CEILING_S)
    finally:
        tab.close()
    events = [json.loads(line) for line in (session / "session.jsonl").read_text().splitlines()]
    kinds = [e["type"] for e in events]
    assert kinds[:4] == ["session", "task", "judgement", "demonstration"], kinds
    search = next(e for e in events if e["type"] == "search")
    assert search["criterion"] == "succeeds" and search["size"] == 1
    assert search["counterfactuals"][0]["edit"][0]["slot"] == "table"
    assert all(c["dropped_at"] == 50 for c in search["tried"] if not c["valid"])
    tuned = next(e for e in events if e["type"] == "finetune")
    assert tuned["feedback"][0]["label"] == "TI" and tuned["n_augmented"] == QUICK.budget - 1
    assert any((p / "model.safetensors").is_file() for p in session.glob("policy-*"))
