"""Take the README's pictures: the feedback page at each stage of the loop (nav2d, and the
tabletop's 3D view), a run's recording in Rerun's web viewer, and what a participant of a user
study sees (`dfa study serve`), all in headless Chromium.

    .venv/bin/python docs/screenshots.py [--out docs/screenshots] [--width 1400 --height 900]

Each picture is a real page or viewer: the page is served in this process on a temporary
session, and the recording is one `dfa run` wrote, served by `rerun --web-viewer`.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import tyro

from dfa_viz.bench.page import ARGS, CHROMIUM


@dataclass(frozen=True)
class Args:
    """Take the README's screenshots of the page and of a recording."""

    out: Path = Path(__file__).parent / "screenshots"
    """Folder for the PNG files."""
    width: int = 1400
    """Browser window width in pixels."""
    height: int = 900
    """Browser window height in pixels."""
    page: bool = True
    """Take the page's pictures."""
    recording: bool = True
    """Take the recordings' pictures in Rerun's web viewer."""
    study: bool = True
    """Take the user study's pictures (what a participant sees)."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def page_shots(browser, args: Args, tmp: Path) -> list[Path]:
    from playwright.sync_api import expect

    from dfa_viz.app.server import open_state, start
    from dfa_viz.configs import AdaptConfig, Finetuning

    quick = AdaptConfig(budget=10, finetuning=Finetuning(steps=100, steps_per_trajectory=1))
    state = open_state(world="nav2d", session=tmp / "s-nav", out=tmp, adapt=quick)
    app = start(port=free_port(), state=state)
    shots: list[Path] = []
    try:
        page = browser.new_page(viewport={"width": args.width, "height": args.height})
        page.set_default_timeout(180_000)
        _open(page, app.url)
        page.get_by_role("button", name="Load task").click()
        page.get_by_role("button", name="Failed").wait_for()
        shots.append(_shot(page, args.out / "page-1-judge.png"))
        page.get_by_role("button", name="Failed").click()
        page.get_by_role("button", name="Ask the expert").wait_for()
        shots.append(_shot(page, args.out / "page-2-demonstrate.png"))
        page.get_by_role("button", name="Ask the expert").click()
        page.get_by_text("Counterfactual found").first.wait_for()
        time.sleep(1.0)
        shots.append(_shot(page, args.out / "page-3-diagnosis.png"))
        page.get_by_role("button", name="Task-irrelevant (TI)").first.click()
        expect(page.get_by_role("button", name="Augment & finetune")).to_be_enabled()
        shots.append(_shot(page, args.out / "page-4-feedback.png"))
        page.get_by_role("button", name="Augment & finetune").click()
        page.get_by_text("fresh tasks with the shift").first.wait_for()
        time.sleep(1.0)
        shots.append(_shot(page, args.out / "page-5-adapted.png"))
        page.close()
    finally:
        app.stop()
    state = open_state(world="tabletop", session=tmp / "s-tab", out=tmp, adapt=quick)
    app = start(port=free_port(), state=state)
    try:
        page = browser.new_page(viewport={"width": args.width, "height": args.height})
        page.set_default_timeout(180_000)
        _open(page, app.url)
        page.get_by_role("button", name="Load task").click()
        page.get_by_role("button", name="Failed").click()
        page.get_by_role("button", name="Ask the expert").click()
        page.get_by_text("Counterfactual found").first.wait_for()
        time.sleep(2.0)
        shots.append(_shot(page, args.out / "page-tabletop-3d.png"))
        page.close()
    finally:
        app.stop()
    return shots


def _open(page, url: str) -> None:
    """Go to the page once it is interactive, and close viser's 'software WebGL' notice."""
    page.goto(url)
    page.get_by_role("button", name="Load task").wait_for()
    _dismiss(page)


def _dismiss(page) -> None:
    """Close viser's 'software WebGL' notice, if it comes."""
    try:
        page.get_by_text("Software WebGL rendering detected").wait_for(timeout=3_000)
    except Exception:
        return
    close = page.locator(".mantine-Notification-closeButton")
    for i in range(close.count()):
        close.nth(i).click()


def _shot(page, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(path))
    return path


def recording_shots(browser, args: Args, tmp: Path) -> list[Path]:
    shots = []
    for world, shift in (("nav2d", "object_ti"), ("tabletop", "distractor_ti")):
        subprocess.run(
            [
                sys.executable,
                "-m",
                "dfa_viz.cli",
                "run",
                "--world",
                world,
                "--shift",
                shift,
                "--seed",
                "0",
                "--out",
                str(tmp),
            ],
            check=True,
            capture_output=True,
        )
        rrd = tmp / f"{world}-{shift}-seed0.rrd"
        web, grpc = free_port(), free_port()
        viewer = subprocess.Popen(
            [
                str(Path(sys.executable).parent / "rerun"),
                str(rrd),
                "--web-viewer",
                "--bind",
                "127.0.0.1",
                "--web-viewer-port",
                str(web),
                "--port",
                str(grpc),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # `rerun` starts the viewer as a child: stop them together
        )
        try:
            time.sleep(4.0)
            url = f"http://127.0.0.1:{web}?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.goto(url)
            time.sleep(25.0)  # the viewer loads the file and lays it out
            shots.append(_shot(page, args.out / f"recording-{world}.png"))
            page.close()
        finally:
            os.killpg(viewer.pid, signal.SIGTERM)
            viewer.wait()
    return shots


def study_shots(browser, args: Args, tmp: Path) -> list[Path]:
    """A small nav2d study (all four conditions, within subjects), frozen and served in this
    process; two participants go through it by keyboard and the first screen of each kind is
    saved: the code, the concepts, a shift example, the counterfactual, a question per
    condition."""
    from dfa_viz.study.answers import read_lines
    from dfa_viz.study.freeze import freeze
    from dfa_viz.study.protocol import Protocol
    from dfa_viz.study.server import start_study

    folder = tmp / "study"
    conditions = ("none", "counterfactual", "saliency", "both")
    freeze(Protocol(tasks=(("nav2d", 1),), conditions=conditions, design="within"), folder)
    app = start_study(folder, port=free_port())
    out: list[Path] = []
    seen: set[str] = set()

    def shot(page, name: str) -> None:
        if name in seen:
            return
        seen.add(name)
        time.sleep(0.8)
        path = args.out / f"study-{len(seen)}-{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(path))
        out.append(path)

    try:
        for pid in (folder / "codes.txt").read_text().split()[:2]:
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.set_default_timeout(60_000)
            page.goto(app.url)
            page.get_by_role("button", name="Start").wait_for()
            _dismiss(page)
            page.get_by_role("textbox").first.fill(pid)
            shot(page, "code")
            page.get_by_role("button", name="Start").click()
            first = page.get_by_text("Introduction 1 of").first
            first.wait_for()
            n = int(first.inner_text().split(" of ")[1].split(":")[0])
            for i in range(1, n + 1):
                title = page.get_by_text(f"Introduction {i} of {n}").first
                title.wait_for()
                page.get_by_role("button", name="(Enter)").wait_for()
                text = title.inner_text()
                for key, name in (
                    ("things", "concepts"),
                    ("change (", "shift"),
                    ("After one", "counterfactual"),
                ):
                    if key in text:
                        shot(page, name)
                page.keyboard.press("Enter")
            plan = read_lines(folder / "answers" / f"{pid}.jsonl")[0]["plan"]
            for j, q in enumerate(plan):
                page.get_by_text(f"Question {j + 1} of {len(plan)}").first.wait_for()
                page.get_by_role("button", name="Submit answer (Enter)").wait_for()
                shot(page, f"question-{q['condition']}")
                for key in ("0", "N", "Enter"):
                    page.keyboard.press(key)
                    time.sleep(0.2)
            page.get_by_text("Thank you!").first.wait_for()
            page.close()
    finally:
        app.stop()
    return out


def main() -> None:
    args = tyro.cli(Args)
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="dfa-shots-") as d, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        shots = page_shots(browser, args, Path(d)) if args.page else []
        shots += recording_shots(browser, args, Path(d)) if args.recording else []
        shots += study_shots(browser, args, Path(d)) if args.study else []
        browser.close()
    for s in shots:
        print(s)


if __name__ == "__main__":
    main()
