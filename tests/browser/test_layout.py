"""Layout facts a first-time user depends on, at the window sizes people use: the
demonstration image is whole and clickable between the panels, a click that misses it says
so, and the active stage's next action, why it waits, the task and the running job's progress
are on screen after every stage."""

from __future__ import annotations

import io

import numpy as np
import pytest
from conftest import WINDOW_SIZES  # tests/browser/conftest.py
from PIL import Image
from playwright.sync_api import expect

pytestmark = pytest.mark.browser

GOAL_RED = (230, 40, 40)  # sim.nav2d.render.COLOURS["red"]


def _image_box(page) -> tuple[float, float, float, float]:
    """Page box of the nav2d task image (its black floor) in the 3D view: the black pixels of
    a screenshot of the page, counted inside the largest canvas only (the panels' black text
    is not the image)."""
    canvases = page.locator("canvas")
    boxes = [canvases.nth(i).bounding_box() for i in range(canvases.count())]
    view = max((b for b in boxes if b), key=lambda b: b["width"] * b["height"])
    img = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB")).astype(int)
    x, y = max(int(view["x"]), 0), max(int(view["y"]), 0)
    img = img[y : int(view["y"] + view["height"]), x : int(view["x"] + view["width"])]
    black = (img.sum(axis=-1) < 30).astype(np.uint8)
    rows, cols = black.sum(axis=1), black.sum(axis=0)
    ys = np.flatnonzero(rows > 0.5 * rows.max())
    xs = np.flatnonzero(cols > 0.5 * cols.max())
    return (
        float(x + xs.min()),
        float(y + ys.min()),
        float(x + xs.max() + 1),
        float(y + ys.max() + 1),
    )


@pytest.mark.parametrize(("width", "height"), WINDOW_SIZES)
def test_the_demonstration_image_is_whole_and_clickable(serve_app, ui, shots, width, height):
    app = serve_app("nav2d")
    page = ui.open(app.url)
    page.set_viewport_size({"width": width, "height": height})
    page.get_by_role("button", name="Load task").click()
    page.get_by_role("button", name="Failed").click()
    next_action = page.get_by_role("button", name="Continue: the expert shows it")
    expect(next_action).to_be_visible()
    assert ui.inside(page, next_action)
    # the compare panel folds into a rail, and the image takes the room it leaves
    page.locator("[data-dock-region=right] [data-dock-column-rail]").wait_for()
    x0, y0, x1, y1 = ui.wait_steady(lambda: _image_box(page), "the demonstration image")
    page.screenshot(path=shots / f"demonstrate-{width}x{height}.png")

    side = min(x1 - x0, y1 - y0)
    assert side >= 240, (x0, y0, x1, y1)  # big enough to aim at (246 px at 1280 x 720)
    assert abs((x1 - x0) - (y1 - y0)) <= 4, "the square image is cut on one side"
    panels = page.locator(".mantine-Paper-root").all()  # the control panel's edge
    left_panel = max(
        (b["x"] + b["width"] for b in (p.bounding_box() for p in panels) if b and b["x"] < 10),
        default=0,
    )
    assert x0 >= left_panel - 1 and x1 <= width and y1 <= height

    x, y = ui.canvas_point(page, GOAL_RED)
    page.mouse.click(x, y)
    ui.wait_for_text(page, "1 waypoint, ends on the goal")
    use = page.get_by_role("button", name="Continue: search with my demonstration")
    expect(use).to_be_enabled()
    assert ui.inside(page, use)

    page.mouse.click(x0 - 20 if x0 > 420 else x1 + 20, (y0 + y1) / 2)  # just off the image
    ui.wait_for_text(page, "that click missed the image")
    use.click()
    ui.wait_for_text(page, "Counterfactual found")
    finetune = page.get_by_role("button", name="Continue: make variants and finetune")
    # the waiting button says why, beside it (in italics; the Adapt section says it too)
    why = page.locator("em", has_text="Mark distractor.presence first.")
    expect(why).to_be_visible()
    expect(finetune).to_be_disabled()
    assert ui.inside(page, finetune) and ui.inside(page, why)
    assert ui.inside(page, page.get_by_text("Task:").first)
    page.get_by_role("button", name="Task-irrelevant (TI)").click()
    expect(finetune).to_be_enabled()
    assert ui.inside(page, finetune)
    expect(page.get_by_role("button", name="✔ Task-irrelevant (TI)")).to_be_visible()
    expect(page.get_by_text("Mark distractor.presence first.")).to_have_count(0)
    finetune.click()
    bar = page.get_by_role("progressbar").first  # while the job runs
    bar.wait_for(state="visible")
    assert ui.inside(page, bar)
    page.screenshot(path=shots / f"finetuning-{width}x{height}.png")
    ui.wait_for_text(page, "fresh tasks with the shift")
    another = page.get_by_role("button", name="Continue: another task")
    expect(another).to_be_visible()
    assert ui.inside(page, another)
    page.screenshot(path=shots / f"adapted-{width}x{height}.png")
