"""The whole loop on every world the picker offers, walked once per world with the expert's
demonstration, and at every stage the window set to each size people use: the next step's
control, why it waits and the running job's progress are inside the window at each of them.

The stages' pictures at 1280x720 are the README's (docs/screenshots/every-world/, copied from
this test's shots folder)."""

from __future__ import annotations

import time

import pytest
from playwright.sync_api import expect

pytestmark = pytest.mark.browser

LAYOUT_S = 30  # a resized page lays itself out in well under a second; a ceiling, not a wait
SIZES = [(1280, 720), (1440, 900), (1920, 1080)]
SMALLEST = {"width": 1280, "height": 720}
WORLDS = ["nav2d", "doorkey", "tabletop"]

# None while no progress bar is drawn, else whether it lies inside the window (one reading of
# the page, so a job that ends between two readings cannot make them disagree)
BAR_INSIDE = """() => {
  const bar = document.querySelector("[role=progressbar]");
  const r = bar && bar.getBoundingClientRect();
  if (!r || r.width === 0) return null;
  return r.x >= 0 && r.y >= 0 && r.right <= innerWidth && r.bottom <= innerHeight;
}"""


def _inside(page, locator) -> bool:
    box = locator.bounding_box()
    size = page.viewport_size
    return (
        box is not None
        and box["x"] >= 0
        and box["y"] >= 0
        and box["x"] + box["width"] <= size["width"]
        and box["y"] + box["height"] <= size["height"]
    )


def _settles(cond, what: str) -> None:
    deadline = time.monotonic() + LAYOUT_S
    while not cond():
        assert time.monotonic() < deadline, f"not within {LAYOUT_S} s: {what}"
        time.sleep(0.1)


def _at_every_size(page, ui, shots, stage: str, *controls) -> None:
    """Each control visible and inside the window at every size (after the page has laid
    itself out again); a picture of the stage at each."""
    for width, height in SIZES:
        page.set_viewport_size({"width": width, "height": height})
        for control in controls:
            expect(control).to_be_visible()
            _settles(
                lambda c=control: _inside(page, c),
                f"{stage}: {c_name(control)} inside {width}x{height}",
            )
        page.screenshot(path=shots / f"{stage}-{width}x{height}.png")


def c_name(locator) -> str:
    return str(locator).removeprefix("<Locator ").removesuffix(">")


@pytest.mark.parametrize("world", WORLDS)
def test_every_stage_in_view_at_every_size(serve_app, ui, shots, world):
    app = serve_app(world)
    page = ui.open(app.url)
    load = page.get_by_role("button", name="Load task")
    _at_every_size(page, ui, shots, "0-pick", load)
    load.click()

    failed = page.get_by_role("button", name="Failed")
    _at_every_size(page, ui, shots, "1-judge", failed, page.get_by_text("Task:").first)
    failed.click()

    expert = page.get_by_role("button", name="Continue: the expert shows it")
    _at_every_size(page, ui, shots, "2-demonstrate", expert)
    expert.click()

    finetune = page.get_by_role("button", name="Continue: make variants and finetune")
    why = page.locator("em", has_text="first.")  # "Mark <concept> first."
    expect(finetune).to_be_disabled()
    _at_every_size(page, ui, shots, "3-feedback", finetune, why)
    marks = page.get_by_role("button", name="Task-irrelevant (TI)", exact=True)
    marked = page.get_by_role("button", name="✔ Task-irrelevant (TI)", exact=True)
    for n in range(1, marks.count() + 1):  # every concept of the counterfactual's edit, TI
        marks.first.click()
        expect(marked).to_have_count(n)
    expect(why).to_have_count(0)
    expect(finetune).to_be_enabled()
    _at_every_size(page, ui, shots, "4-marked", finetune)

    page.set_viewport_size(SMALLEST)  # the job's progress in view at the smallest size
    finetune.click()
    _settles(lambda: page.evaluate(BAR_INSIDE) is not None, "the finetuning's progress bar")
    assert page.evaluate(BAR_INSIDE), "the progress bar is outside the window"
    page.screenshot(path=shots / "5-finetuning-1280x720.png")
    ui.wait_for_text(page, "fresh tasks with the shift")
    another = page.get_by_role("button", name="Continue: another task")
    _at_every_size(page, ui, shots, "6-adapted", another)
