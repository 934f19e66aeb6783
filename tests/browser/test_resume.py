"""Kill the server mid-session, start it again on the same session, find everything there."""

from __future__ import annotations

import json

import pytest
from conftest import ChildServer  # tests/browser/conftest.py
from playwright.sync_api import expect

pytestmark = pytest.mark.browser


class Server(ChildServer):
    """`python -m dfa_viz.cli serve --session SESSION` as a child process."""

    def __init__(self, session, cwd) -> None:
        super().__init__(["serve", "--session", str(session)], cwd)


def test_kill_and_resume_keeps_the_marks(ui, tmp_path, shots):
    session = tmp_path / "session"
    first = Server(session, tmp_path)
    try:
        page = ui.open(first.url)
        page.get_by_role("button", name="Load task").click()
        page.get_by_role("button", name="Failed").click()
        page.get_by_role("button", name="Ask the expert").click()
        ui.wait_for_text(page, "Counterfactual found")
        page.get_by_role("button", name="Task-irrelevant (TI)").click()
        ui.wait_for_text(page, "variants may take: present or absent")
        page.get_by_role("checkbox", name="absent").uncheck()
        ui.wait_for_text(page, "variants may take: only present")  # acknowledged: it is on disk
        page.screenshot(path=shots / "0-before-kill.png")
    finally:
        first.kill()

    log = [json.loads(x) for x in (session / "session.jsonl").read_text().splitlines()]
    assert [e["type"] for e in log][-2:] == ["mark", "mark"]
    assert log[-1]["acceptable"] == ["present"]

    second = Server(session, tmp_path)
    try:
        page = ui.open(second.url)
        ui.wait_for_text(page, "variants may take: only present")
        expect(page.get_by_text("Counterfactual found")).to_be_visible()
        expect(page.get_by_role("checkbox", name="present")).to_be_checked()
        expect(page.get_by_role("checkbox", name="absent")).not_to_be_checked()
        expect(page.get_by_role("button", name="Augment & finetune")).to_be_enabled()
        page.screenshot(path=shots / "1-resumed.png")
        # the folder grew by nothing but what the user did: same log, same demonstration
        again = [json.loads(x) for x in (session / "session.jsonl").read_text().splitlines()]
        assert again == log
    finally:
        second.kill()
