"""The Sweep tab, driven in Chromium: run the sweep, click a cell of the heatmap in the 3D view,
and the failure it stands for is loaded as the task to diagnose."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import expect

from dfa_viz.app.sweep import padded
from dfa_viz.sweep.figures import NOT_APPLIED

pytestmark = pytest.mark.browser

GREY = np.array([round(255 * c) for c in NOT_APPLIED])  # cells that never apply


def _grey_box(img: np.ndarray) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1) of the pixels inside solid blocks of the never-applies grey (a pixel
    whose 3x3 neighbourhood is all that grey: no letter's edge)."""
    grey = (np.abs(img.astype(int) - GREY).sum(axis=-1) < 12).astype(np.uint8)  # (H, W)
    solid = grey[1:-1, 1:-1].copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            solid &= grey[1 + dy : grey.shape[0] - 1 + dy, 1 + dx : grey.shape[1] - 1 + dx]
    ys, xs = np.nonzero(solid)
    assert len(xs), "no never-applies cell in sight"
    return xs.min() + 1.0, ys.min() + 1.0, xs.max() + 1.0, ys.max() + 1.0


def _view(page):
    """The 3D view's canvas (the largest one) and its box on the page."""
    canvases = page.locator("canvas")
    boxes = [canvases.nth(i).bounding_box() for i in range(canvases.count())]
    i = int(np.argmax([b["width"] * b["height"] if b else 0 for b in boxes]))
    return canvases.nth(i), boxes[i]


def test_a_heatmap_click_loads_that_failure(serve_app, ui, shots):
    app = serve_app("nav2d")
    page = ui.open(app.url)
    page.get_by_role("tab", name="Sweep").click()
    page.get_by_role("button", name="Run sweep").click()
    ui.wait_until(lambda: app.state.sweep is not None, "the sweep")
    shown = app.state.sweep
    expect(page.get_by_text("goal.colour=blue").first).to_be_visible()
    expect(page.get_by_role("checkbox")).to_be_checked()
    target = shown.result.cells[0]
    assert target.key == ("goal", "colour", "blue") and target.failure_rate == 1.0

    # where the heatmap lies on the screen: its grey cells' box there and in the image
    square, (ox, oy) = padded(shown.heatmap.image)
    canvas, box = _view(page)

    def screen():
        shot = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB"))
        return shot, _grey_box(shot)

    ui.wait_until(lambda: _has_grey(canvas), "the heatmap in the 3D view")
    shot, (sx0, sy0, sx1, sy1) = screen()
    ix0, iy0, ix1, iy1 = _grey_box(square)
    u, v = shown.heatmap.centre(target.key)  # in the unpadded image
    h, w = shown.heatmap.image.shape[:2]
    px, py = ox + u * w, oy + v * h  # in the padded one
    kx, ky = box["width"] / shot.shape[1], box["height"] / shot.shape[0]
    x = box["x"] + kx * (sx0 + (px - ix0) * (sx1 - sx0) / (ix1 - ix0))
    y = box["y"] + ky * (sy0 + (py - iy0) * (sy1 - sy0) / (iy1 - iy0))
    page.screenshot(path=shots / "1-heatmap.png")
    page.mouse.click(x, y)

    # the failure is the task now: a training task with the goal turned blue, to diagnose
    ui.wait_until(lambda: app.state.record is not None, "the task to load")
    rec = app.state.record
    assert rec.shift == "sweep" and rec.seed == target.example.seed
    assert rec.task.scene.obj("goal").value("colour") == "blue"
    assert not rec.rollout.success
    expect(page.get_by_role("checkbox")).not_to_be_checked()
    events = [json.loads(x) for x in app.state.session.path.read_text().splitlines()]
    assert events[-1]["type"] == "task" and events[-1]["edit"] == [
        {"slot": "goal", "concept": "colour", "from": "red", "to": "blue"}
    ]
    page.get_by_role("tab", name="Compare").click()
    page.get_by_role("button", name="Failed").click()
    page.get_by_role("button", name="Ask the expert").click()
    ui.wait_for_text(page, "Counterfactual found")
    expect(page.get_by_text("goal.colour: blue → red").first).to_be_visible()
    page.screenshot(path=shots / "2-diagnosed.png")


def _has_grey(canvas) -> bool:
    shot = np.asarray(Image.open(io.BytesIO(canvas.screenshot())).convert("RGB"))
    try:
        _grey_box(shot)
    except AssertionError:
        return False
    return True
