"""DoorKey demonstrated with the keyboard in the page."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

pytestmark = pytest.mark.browser

# sim.doorkey.layout: LEFT, RIGHT, FORWARD, PICKUP, DROP, TOGGLE -> the page's hotkeys
KEYS = {0: "ArrowLeft", 1: "ArrowRight", 2: "ArrowUp", 3: "p", 4: "d", 5: "t"}


def test_doorkey_demonstration_by_keys(serve_app, ui, shots):
    pytest.importorskip("minigrid")
    from search import compared_steps

    app = serve_app("doorkey")
    page = ui.open(app.url)
    page.get_by_role("button", name="Load task").click()  # doorkey, distractor_ti, seed 0
    page.get_by_role("button", name="Failed").click()
    expect(page.get_by_role("button", name="turn left")).to_be_visible()

    run = app.state.run
    expert = run.world.demonstrate(run.task)
    n = compared_steps(run.world, expert)  # steps until the goal
    actions = [int(a) for a in expert.actions[:n]]
    page.get_by_text("Show what you wanted").click()  # focus the page, not an input
    for i, a in enumerate(actions[:-1]):
        page.keyboard.press(KEYS[a])
        expect(page.get_by_text(f"{i + 1} steps:")).to_be_visible()
    page.get_by_role("button", name="forward" if actions[-1] == 2 else "toggle").click()
    expect(page.get_by_text("(episode over)")).to_be_visible()
    page.screenshot(path=shots / "0-demonstrated.png")
    page.get_by_role("button", name="Use my demonstration").click()
    page.get_by_text("edits tried").first.wait_for()
    page.screenshot(path=shots / "1-diagnosis.png")

    demo = app.state.run.demo
    assert demo.success
    assert [int(a) for a in demo.actions[:n]] == actions
    assert demo.scenes[: n + 1] == expert.scenes[: n + 1]
    assert app.state.run.demo_source == "keys"
