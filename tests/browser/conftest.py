"""Fixtures for driving the real page in Debian's Chromium through playwright."""

from __future__ import annotations

import io
import os
import re
import socket
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect

from dfa_viz.bench.page import ARGS, CHROMIUM, WAIT_S  # one launch recipe for tests and bench
from dfa_viz.configs import AdaptConfig, Finetuning

VIEWPORT = {"width": 1600, "height": 1000}
WINDOW_SIZES = [(1280, 720), (1440, 900), (1920, 1080)]  # the window sizes people use
LAYOUT_S = 120  # a resized page lays itself out in well under a second; a ceiling, not a wait
# Every wait here is for something the page shows (a text, an enabled button, the session's
# state) and ends as soon as it is there. WAIT_S is a ceiling, not an expectation: it only turns
# a page that never gets there into a failure. A job (loading a policy, a search, finetuning)
# takes minutes on two cores that other work keeps busy; speed is measured by `dfa bench`.
TEST_S = 60 * 60  # pytest-timeout for one test in this folder: a few jobs and one ceiling
expect.set_options(timeout=WAIT_S * 1000)
# a budget of 10 and 60 steps take nav2d distractor_ti seed 2 from 30% to 70% on the shift (4
# of its 10 distinct fresh tasks newly solved, on 1 and 2 torch threads) and keep the suite quick
QUICK = AdaptConfig(budget=10, finetuning=Finetuning(steps=60, steps_per_trajectory=1))
OUTPUT = Path(os.environ.get("DFA_TEST_OUTPUT", "recordings/test-output")) / "browser"


def pytest_collection_modifyitems(items) -> None:
    """Every test in this folder drives Chromium: marked `browser`, with TEST_S to run."""
    here = Path(__file__).parent
    for item in items:
        if item.path.is_relative_to(here):
            item.add_marker(pytest.mark.browser)
            if item.get_closest_marker("timeout") is None:
                item.add_marker(pytest.mark.timeout(TEST_S))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def browser():
    if not Path(CHROMIUM).exists():
        pytest.fail(f"{CHROMIUM} is missing: apt-get install -y --no-install-recommends chromium")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


@pytest.fixture
def shots(request) -> Path:
    """Where this test saves its screenshots."""
    folder = OUTPUT / request.node.name.replace("[", "-").replace("]", "")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@pytest.fixture
def serve_app(tmp_path):
    """Start the page in this process: serve_app(world, session, policy) -> App; stopped at
    teardown. `policy`: a policy spec to diagnose instead of the world's base policy."""
    from dfa_viz.app import start
    from dfa_viz.app.server import open_state

    apps = []

    def make(world: str = "nav2d", session: Path | None = None, policy: str | None = None):
        state = open_state(
            world=world,
            session=session or tmp_path / f"session-{len(apps)}",
            out=tmp_path / "recordings",
            adapt=QUICK,
            policy=policy,
        )
        app = start(port=free_port(), state=state)
        apps.append(app)
        return app

    yield make
    for app in apps:
        app.stop()


# True where viser's page will show "Software WebGL rendering detected" (its BrowserWarning.tsx).
SOFTWARE_WEBGL = """() => {
  let gl = null;
  try {
    const canvas = document.createElement("canvas");
    gl = canvas.getContext("webgl2") || canvas.getContext("webgl");
  } catch (e) {
    return false;
  }
  const info = gl && gl.getExtension("WEBGL_debug_renderer_info");
  if (!info) return false;
  const name = String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL) ?? "").toLowerCase();
  gl.getExtension("WEBGL_lose_context")?.loseContext();
  return ["swiftshader", "llvmpipe", "softpipe", "software"].some((s) => name.includes(s));
}"""


class UI:
    """Helpers that act on a page the way a user does."""

    def __init__(self, browser) -> None:
        self.browser = browser
        self.pages = []

    def open(self, url: str):
        """A new tab on the page, once it is interactive."""
        page = self.browser.new_page(viewport=VIEWPORT)
        page.set_default_timeout(WAIT_S * 1000)
        self.pages.append(page)
        page.goto(url)
        page.get_by_role("button", name="Load task").wait_for()
        self.dismiss_notifications(page)
        return page

    @staticmethod
    def dismiss_notifications(page) -> None:
        """Close viser's 'software WebGL' notice so that it covers nothing. Whether the page
        shows it is decided the way viser decides it (BrowserWarning.tsx: the WebGL renderer's
        name), so the notice is waited for exactly when it comes."""
        if not page.evaluate(SOFTWARE_WEBGL):
            return
        notice = page.get_by_text("Software WebGL rendering detected")
        notice.wait_for()
        close = page.locator(".mantine-Notification-closeButton")
        for i in range(close.count()):
            close.nth(i).click()
        notice.wait_for(state="hidden")

    @classmethod
    def canvas_point(cls, page, rgb, *, tol: int = 40) -> tuple[float, float]:
        """Page coordinates of the centre of the pixels of colour `rgb` in the 3D view, once
        they are drawn there and have stopped moving."""

        def read() -> tuple[float, float] | None:
            canvases = page.locator("canvas")
            boxes = [canvases.nth(i).bounding_box() for i in range(canvases.count())]
            areas = [b["width"] * b["height"] if b else 0 for b in boxes]
            canvas = canvases.nth(int(np.argmax(areas)))  # the 3D view, not a plot
            box = boxes[int(np.argmax(areas))]
            img = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB"))
            ys, xs = np.nonzero(np.abs(img.astype(int) - np.array(rgb)).sum(axis=-1) < tol)
            if not len(xs):
                return None
            sx, sy = box["width"] / img.shape[1], box["height"] / img.shape[0]
            # the median: the red axis of viser's orientation gizmo must not pull it away
            return box["x"] + float(np.median(xs)) * sx, box["y"] + float(np.median(ys)) * sy

        cls.wait_until(lambda: read() is not None, f"a pixel of colour {rgb} in the 3D view")
        return cls.wait_steady(read, f"the pixels of colour {rgb}")

    @staticmethod
    def frames(page):
        """The compare strip image (the only blob-URL image on the page)."""
        return page.locator("img[src^='blob:']").first

    @staticmethod
    def wait_for_text(page, text: str):
        page.get_by_text(text).first.wait_for()
        return page.get_by_text(text).first

    @staticmethod
    def success(page) -> tuple[int, int]:
        """(before, after) percentages from the adaptation result."""
        text = page.get_by_text("fresh tasks with the shift").first.inner_text()
        m = re.search(r"(\d+)% → (\d+)%", text)
        assert m, text
        return int(m.group(1)), int(m.group(2))

    @staticmethod
    def inside(page, locator) -> bool:
        """Whether the element lies wholly inside the window (not scrolled or cut off)."""
        box, size = locator.bounding_box(), page.viewport_size
        return (
            box is not None
            and box["x"] >= 0
            and box["y"] >= 0
            and box["x"] + box["width"] <= size["width"]
            and box["y"] + box["height"] <= size["height"]
        )

    @classmethod
    def in_view_at_every_size(cls, page, *controls, shots=None, stage: str = "") -> None:
        """Each control visible and wholly inside the window at every size of WINDOW_SIZES,
        once the page has laid itself out again (LAYOUT_S at most); with `shots`, a picture
        at each size named after `stage`. The window is left at the last size."""
        for width, height in WINDOW_SIZES:
            page.set_viewport_size({"width": width, "height": height})
            deadline = time.monotonic() + LAYOUT_S
            for control in controls:
                while not cls.inside(page, control):
                    assert time.monotonic() < deadline, (
                        f"{stage} {control}: not in {width}x{height}"
                    )
                    time.sleep(0.1)
            if shots is not None:
                page.screenshot(path=shots / f"{stage}-{width}x{height}.png")

    @staticmethod
    def wait_until(cond, what: str) -> None:
        """Poll `cond` until it holds (WAIT_S at most)."""
        deadline = time.monotonic() + WAIT_S
        while not cond():
            assert time.monotonic() < deadline, f"waited {WAIT_S} s for {what}"
            time.sleep(0.05)

    @staticmethod
    def wait_steady(read, what: str):
        """Poll `read` until two readings in a row are equal (something that moved has come
        to rest); that reading. WAIT_S at most."""
        deadline, last = time.monotonic() + WAIT_S, read()
        while (now := read()) != last:
            assert time.monotonic() < deadline, f"{what} still moving after {WAIT_S} s"
            last = now
        return now

    def close(self) -> None:
        for p in self.pages:
            p.close()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if report.when == "call":
        item.failed_call = report.failed
    return report


@pytest.fixture
def ui(browser, request, shots):
    helper = UI(browser)
    yield helper
    if getattr(request.node, "failed_call", False):  # keep what the pages showed
        for i, page in enumerate(helper.pages):
            page.screenshot(path=shots / f"failure-tab{i}.png")
    helper.close()


class ChildServer:
    """`python -m dfa_viz.cli ARGS --port N` as a child process, so that a test can really
    crash it (SIGKILL); `url` once it has printed "the page is at URL"."""

    def __init__(self, args: list[str], cwd=None) -> None:
        import subprocess
        import sys
        import threading

        self.lines: list[str] = []
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "dfa_viz.cli", *args, "--port", str(free_port())],
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

    def _wait_for(self, pattern: str) -> str:
        """The first group of `pattern` in the child's output, once it is there (the child
        ending first, or WAIT_S passing, is a failure)."""
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            for line in self.lines:
                if m := re.search(pattern, line):
                    return m.group(1)
            assert self.proc.poll() is None, "".join(self.lines)
            time.sleep(0.1)
        raise AssertionError(f"no {pattern!r} in:\n{''.join(self.lines)}")

    def kill(self) -> None:
        import signal

        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)  # a crash: no clean shutdown
            self.proc.wait(timeout=30)
        self._drainer.join(timeout=10)
        self.proc.stdout.close()
