"""The page on a closed-loop MuJoCo world (`dfa serve --world fetch:FetchPickAndPlace-v4`): the
failed rollout, a demonstration given by clicking the gripper's waypoints on the image (the
block, then the target: in both views where it is in the air) and the search, answered in the
world's terms, then TI feedback and a finetuned policy, every step on disk in the session."""

from __future__ import annotations

import json

import pytest
from clicked import click_on, drawn
from page_wire import CEILING_S, PageWire, free_port

from dfa_viz.app.canvas import SIZE
from dfa_viz.app.feedback import TI
from dfa_viz.app.page import FINETUNE, USE_DEMO
from dfa_viz.configs import AdaptConfig, Finetuning

FETCH = "fetch:FetchPickAndPlace-v4"
# variants of the user's demonstration, no replay: the page's flow, without the base policy's
# 200 training demonstrations and relabelled rollouts (minutes; the replay itself is tested in
# tests/policy/test_dagger.py)
QUICK = AdaptConfig(
    budget=3, finetuning=Finetuning(steps=10, replay_share=0.0, sources="user", n_eval=2)
)


@pytest.fixture
def served(tmp_path):
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    state = open_state(world=FETCH, session=tmp_path / "s", out=tmp_path / "rec", adapt=QUICK)
    app = start(port=free_port(), state=state)
    yield app, state, tmp_path / "s"
    app.stop()


def test_the_page_diagnoses_and_adapts_the_fetch_policy(served):
    app, state, session = served
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
        tab.wait(lambda: tab.find("Use my demonstration", "Button"), "the clicks", CEILING_S)
        for u, v in _clicks(state):  # on the image, as wide as the frame, SIZE wide
            tab.click_scene((u - 0.5) * SIZE, (0.5 - v) * SIZE / 2)
        tab.wait(lambda: tab.enabled(USE_DEMO), "the clicked demonstration done", CEILING_S)
        assert "2 waypoints: grasp the object, then " in tab.text(), tab.text()
        tab.click(USE_DEMO)
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
    assert events[3]["source"] == "clicks", events[3]
    search = next(e for e in events if e["type"] == "search")
    assert search["criterion"] == "succeeds" and search["size"] == 1
    assert search["counterfactuals"][0]["edit"][0]["slot"] == "table"
    assert all(c["dropped_at"] == 50 for c in search["tried"] if not c["valid"])
    tuned = next(e for e in events if e["type"] == "finetune")
    assert tuned["feedback"][0]["label"] == "TI" and tuned["n_augmented"] == QUICK.budget - 1
    assert any((p / "model.safetensors").is_file() for p in session.glob("policy-*"))


def _clicks(state) -> list[tuple[float, float]]:
    """(u, v) on the frame of the loaded task: the block, then the target (then the target in
    the low view beside it where it is in the air)."""
    world, scene = state.world, state.record.task.scene
    target = drawn(world, scene, "target")
    clicks = [click_on(world, drawn(world, scene, "object"), 0), click_on(world, target, 0)]
    if world.goal_of(scene)[2] > 0.45:  # over the table top (0.4 m) and a block's height
        clicks.append(click_on(world, target, 1))
    return clicks
