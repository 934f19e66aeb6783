"""Faults of the feedback page in Chromium: two tabs pressing the same buttons at the same
moment, and control values the page never offered, sent through the page's own WebSocket.

Both tabs live in one browser context, so that a BroadcastChannel reaches both: one message
makes each tab press the same button at once (no clock). viser's page talks to the server from
a worker (WebsocketClientWorker.ts: {type: "send", message} is msgpack-encoded and sent); the
tests keep that worker and hand it a forged GuiUpdateMessage, exactly as the page would send it.
"""

from __future__ import annotations

import json
import shutil

import pytest
from conftest import UI, VIEWPORT  # tests/browser/conftest.py
from playwright.sync_api import expect

from dfa_viz.app.page import ASK_EXPERT, FINETUNE, NEXT_TASK
from dfa_viz.bench.page import WAIT_S

pytestmark = pytest.mark.browser

# run in every page before its own scripts
SETUP = """(() => {
  // the worker that holds the page's WebSocket, so that a test can send through it
  const Base = window.Worker;
  window.Worker = class extends Base {
    constructor(...args) {
      super(...args);
      window.__viserWorker = this;
    }
  };
  // on a message of channel "dfa-race", press the button whose text it names
  new BroadcastChannel("dfa-race").onmessage = (e) => {
    const button = [...document.querySelectorAll("button")].find(
      (b) => b.innerText.trim() === e.data
    );
    button.click();
  };
})();"""
FORGE = """([uuid, value]) => window.__viserWorker.postMessage({
  type: "send",
  message: {type: "GuiUpdateMessage", uuid: uuid, updates: {value: value}},
})"""


@pytest.fixture
def tabs(browser, request, shots):
    """open(url) -> a tab of one shared browser context, with SETUP run in it."""
    context = browser.new_context(viewport=VIEWPORT)
    context.add_init_script(SETUP)
    pages = []

    def open_tab(url: str):
        page = context.new_page()
        page.set_default_timeout(WAIT_S * 1000)
        pages.append(page)
        page.goto(url)
        page.get_by_role("button", name="Load task").wait_for()
        UI.dismiss_notifications(page)
        return page

    yield open_tab
    if getattr(request.node, "failed_call", False):
        for i, page in enumerate(pages):
            page.screenshot(path=shots / f"failure-tab{i}.png")
    context.close()


def _events(app) -> list[dict]:
    return [json.loads(x) for x in app.state.session.path.read_text().splitlines()]


def _press_at_once(pages, name: str) -> None:
    """Every tab presses the button `name` on one broadcast message, once it can."""
    for page in pages:
        expect(page.get_by_role("button", name=name, exact=True)).to_be_enabled()
    pages[0].evaluate("name => new BroadcastChannel('dfa-race').postMessage(name)", name)


def _task_controls(page) -> tuple[str, str, str]:
    return tuple(
        page.get_by_role(role, name=name).input_value()
        for role, name in (("combobox", "world"), ("combobox", "shift"), ("textbox", "seed"))
    )


def test_two_tabs_pressing_the_same_buttons_at_once(serve_app, tabs, capfd, shots, tmp_path):
    from dfa_viz.app.server import open_state

    app = serve_app("nav2d")
    a, b = tabs(app.url), tabs(app.url)
    pages = [a, b]
    _press_at_once(pages, "Load task")
    _press_at_once(pages, "Failed")
    _press_at_once(pages, ASK_EXPERT)
    _press_at_once(pages, "Task-irrelevant (TI)")
    for page in pages:
        expect(page.get_by_text("variants may take: present or absent")).to_be_visible()
    _press_at_once(pages, FINETUNE)
    for page in pages:
        expect(page.get_by_role("button", name=NEXT_TASK)).to_be_enabled()
    assert UI.success(a) == UI.success(b)
    for page, name in ((a, "a"), (b, "b")):
        page.screenshot(path=shots / f"adapted-{name}.png")
    live = app.state.record
    adapted = tmp_path / "adapted"
    shutil.copytree(app.state.session.folder, adapted)
    _press_at_once(pages, NEXT_TASK)
    for page in pages:
        expect(page.get_by_text("distractor_ti · seed 1").first).to_be_visible()
        expect(page.get_by_role("button", name="Failed")).to_be_enabled()
    assert _task_controls(a) == _task_controls(b) == ("nav2d", "distractor_ti", "1")

    kinds = [e["type"] for e in _events(app)]
    assert kinds == [
        "session",
        *("task", "judgement", "demonstration", "search", "mark", "finetune"),
        "task",
    ]
    folder = app.state.session.folder
    assert len([p for p in folder.iterdir() if p.name.startswith("policy-")]) == 1
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err, (out + err)[-3000:]

    again = open_state(session=adapted, out=tmp_path / "replayed")
    try:
        assert again.snapshot().stage == "adapted"
        assert again.record.task == live.task and again.record.feedback == live.feedback
        assert again.record.evaluation == live.evaluation
    finally:
        again.close()


def test_a_forged_value_from_the_pages_own_socket_is_refused(serve_app, tabs, capfd, shots):
    app = serve_app("nav2d")
    page, other = tabs(app.url), tabs(app.url)
    world = page.get_by_role("combobox", name="world")
    seed = page.get_by_role("textbox", name="seed")
    for control, value, line in [
        (world, "minigrid:MiniGrid-Empty-5x5-v0", "world 'minigrid:MiniGrid-Empty-5x5-v0'"),
        (seed, -4, "seed -4 was not offered"),
    ]:
        page.evaluate(FORGE, [control.get_attribute("id"), value])
        expect(page.get_by_text(f"{line}").first).to_be_visible()
    page.screenshot(path=shots / "refused.png")
    assert page.get_by_text("Refused").count() >= 1
    assert other.get_by_text("Refused").count() == 0  # only the tab that sent it is told
    assert _task_controls(page) == ("nav2d", "distractor_ti", "0")  # shown as it was
    # a forged value and a press sent together: the task is the one the page offered
    page.evaluate(FORGE, [seed.get_attribute("id"), 10**12])
    page.get_by_role("button", name="Load task").click()
    expect(page.get_by_role("button", name="Failed")).to_be_enabled()
    tasks = [e for e in _events(app) if e["type"] == "task"]
    assert [(e["world"], e["shift"], e["seed"]) for e in tasks] == [("nav2d", "distractor_ti", 0)]
    out, err = capfd.readouterr()
    assert "Traceback" not in out + err, (out + err)[-3000:]
