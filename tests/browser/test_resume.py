"""Kill the server mid-session, start it again on the same session, find everything there."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest
from playwright.sync_api import expect

pytestmark = pytest.mark.browser


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """`python -m dfa_viz.cli serve` as a child process."""

    def __init__(self, session, cwd) -> None:
        self.lines: list[str] = []
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "dfa_viz.cli",
                "serve",
                "--port",
                str(free_port()),
                "--session",
                str(session),
            ],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self._drainer = threading.Thread(target=self._drain, daemon=True)
        self._drainer.start()
        self.url = self._wait_for(r"the page is at (http://127\.0\.0\.1:\d+)")

    def _drain(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)

    def _wait_for(self, pattern: str, timeout_s: float = 120.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for line in self.lines:
                if m := re.search(pattern, line):
                    return m.group(1)
            assert self.proc.poll() is None, "".join(self.lines)
            time.sleep(0.1)
        raise AssertionError(f"no {pattern!r} in:\n{''.join(self.lines)}")

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)  # a crash: no clean shutdown
            self.proc.wait(timeout=30)
        self._drainer.join(timeout=10)
        self.proc.stdout.close()


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
        ui.wait_for_text(page, "acceptable: present, absent")
        page.get_by_role("checkbox", name="absent").uncheck()
        ui.wait_for_text(page, "acceptable: present")  # acknowledged: it is on disk
        page.screenshot(path=shots / "0-before-kill.png")
    finally:
        first.kill()

    log = [json.loads(x) for x in (session / "session.jsonl").read_text().splitlines()]
    assert [e["type"] for e in log][-2:] == ["mark", "mark"]
    assert log[-1]["acceptable"] == ["present"]

    second = Server(session, tmp_path)
    try:
        page = ui.open(second.url)
        ui.wait_for_text(page, "acceptable: present")
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
