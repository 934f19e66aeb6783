"""`dfa serve --demos DIR` in Chromium: the demonstrate step's dropdown lists the dataset's
episodes that start from the task's scene; one that does not succeed is refused in one line on
the page; the chosen demonstration is replayed, searched with, shown beside the counterfactual,
and still there when the session is resumed without the dataset.

The dataset is made here by `dfa run --lerobot` on nav2d with small settings.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import QUICK, free_port  # tests/browser/conftest.py
from playwright.sync_api import expect

from dfa_viz.app.episodes import DemoEpisodes
from dfa_viz.app.picker import USE_EPISODE
from dfa_viz.cli import main

pytestmark = pytest.mark.browser
TINY = ["--budget", "3", "--steps", "10", "--n-eval", "2", "--max-size", "1"]
DEMONSTRATION = "episode 0 · demonstration · succeeds · 20 steps"
FAILED = "episode 4 · failed · fails · 20 steps"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """nav2d object_ti seed 0 run by `dfa run --lerobot`: 6 episodes, 3 from the task's scene."""
    tmp = tmp_path_factory.mktemp("demos")
    code = main(
        ["run", "--world", "nav2d", "--shift", "object_ti", "--seed", "0", *TINY,
         "--out", str(tmp / "rec"), "--lerobot", str(tmp / "ds")]
    )  # fmt: skip
    assert code == 0
    return tmp / "ds"


@pytest.fixture
def serve(tmp_path):
    """serve(demos, session) -> the page served in this process; stopped at teardown."""
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    apps = []

    def make(demos: Path | None, session: Path):
        state = open_state(
            session=session,
            out=tmp_path / "recordings",
            adapt=QUICK,
            demos=None if demos is None else DemoEpisodes(demos),
        )
        app = start(port=free_port(), state=state)
        apps.append(app)
        return app

    yield make
    for app in apps:
        app.stop()


def _choose(page, label: str) -> None:
    page.get_by_role("combobox", name="dataset episode").click()
    page.get_by_role("option", name=label, exact=True).click()
    expect(page.get_by_role("combobox", name="dataset episode")).to_have_value(label)


def test_a_dataset_episode_is_the_demonstration(dataset, serve, ui, shots, tmp_path):
    app = serve(dataset, tmp_path / "session")
    page = ui.open(app.url)
    page.get_by_role("combobox", name="shift").click()
    page.get_by_role("option", name="object_ti", exact=True).click()
    page.get_by_role("button", name="Load task").click()
    expect(page.get_by_text("object_ti · seed 0")).to_be_visible()
    page.get_by_role("button", name="Failed").click()

    # the dropdown lists the episodes that start from this task's scene, the first chosen
    ui.wait_for_text(page, "3 of the 6 episodes of")
    episode = page.get_by_role("combobox", name="dataset episode")
    expect(episode).to_have_value(DEMONSTRATION)
    episode.click()
    expect(page.get_by_role("option")).to_have_text(
        [DEMONSTRATION, FAILED, "episode 5 · finetuned · succeeds · 20 steps"]
    )
    page.keyboard.press("Escape")
    expect(page.get_by_role("button", name="Use my demonstration")).to_be_visible()
    expect(page.get_by_role("button", name="Ask the expert")).to_be_visible()
    page.screenshot(path=shots / "1-episodes.png")

    # the failed rollout does not succeed: one line on the page, nothing saved
    _choose(page, FAILED)
    page.get_by_role("button", name=USE_EPISODE).click()
    ui.wait_for_text(page, f"{dataset} episode 4 demonstration does not succeed")
    page.screenshot(path=shots / "2-refused.png")
    folder = app.state.session.folder
    assert "demonstration" not in (folder / "session.jsonl").read_text()

    # the demonstration: replayed, searched with, the counterfactual beside it
    _choose(page, DEMONSTRATION)
    page.get_by_role("button", name=USE_EPISODE).click()
    ui.wait_for_text(page, "Counterfactual found")
    (change, *_) = app.state.record.edit.ordered
    edit = f"{change.slot}.{change.concept}: {change.old} → {change.new}"
    assert edit.startswith("goal.shape: square → ")  # the planted cause
    expect(page.get_by_text(edit).first).to_be_visible()
    expect(page.get_by_role("button", name="Task-irrelevant (TI)")).to_be_visible()
    page.screenshot(path=shots / "3-counterfactual.png")
    events = [json.loads(x) for x in (folder / "session.jsonl").read_text().splitlines()]
    assert [e["type"] for e in events] == [
        "session",
        "task",
        "judgement",
        "demonstration",
        "search",
    ]
    assert events[3]["source"] == f"{dataset} episode 0"

    # resumed without the dataset: the same demonstration and counterfactual
    app.stop()
    again = serve(None, folder)
    page = ui.open(again.url)
    ui.wait_for_text(page, "Counterfactual found")
    expect(page.get_by_text(edit).first).to_be_visible()
    expect(page.get_by_role("combobox", name="dataset episode")).to_be_hidden()
    assert again.state.record.demo_source == f"{dataset} episode 0"
    page.screenshot(path=shots / "4-resumed.png")
