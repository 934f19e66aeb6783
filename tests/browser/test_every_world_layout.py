"""The whole loop on every world the picker offers, walked once per world with the expert's
demonstration, and at every stage the window set to each size people use: the next step's
control, why it waits and the running job's progress are inside the window at each of them.

The stages' pictures at 1280x720 are the README's (docs/screenshots/every-world/, copied from
this test's shots folder)."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from dfa_viz.app.offers import Offers

pytestmark = pytest.mark.browser

SMALLEST = {"width": 1280, "height": 720}
WORLDS = Offers.for_session("nav2d").worlds  # the worlds the picker lists

# None while no progress bar is drawn, else whether it lies inside the window (one reading of
# the page, so a job that ends between two readings cannot make them disagree)
BAR_INSIDE = """() => {
  const bar = document.querySelector("[role=progressbar]");
  const r = bar && bar.getBoundingClientRect();
  if (!r || r.width === 0) return null;
  return r.x >= 0 && r.y >= 0 && r.right <= innerWidth && r.bottom <= innerHeight;
}"""


@pytest.mark.parametrize("world", WORLDS)
def test_every_stage_in_view_at_every_size(serve_app, ui, shots, world):
    app = serve_app(world)
    page = ui.open(app.url)
    load = page.get_by_role("button", name="Load task")
    ui.in_view_at_every_size(page, load, shots=shots, stage="0-pick")
    load.click()

    failed = page.get_by_role("button", name="Failed")
    ui.in_view_at_every_size(
        page, failed, page.get_by_text("Task:").first, shots=shots, stage="1-judge"
    )
    failed.click()

    expert = page.get_by_role("button", name="Continue: the expert shows it")
    ui.in_view_at_every_size(page, expert, shots=shots, stage="2-demonstrate")
    expert.click()

    finetune = page.get_by_role("button", name="Continue: make variants and finetune")
    why = page.locator("em", has_text="first.")  # "Mark <concept> first."
    expect(finetune).to_be_disabled()
    ui.in_view_at_every_size(page, finetune, why, shots=shots, stage="3-feedback")
    marks = page.get_by_role("button", name="Task-irrelevant (TI)", exact=True)
    marked = page.get_by_role("button", name="✔ Task-irrelevant (TI)", exact=True)
    for n in range(1, marks.count() + 1):  # every concept of the counterfactual's edit, TI
        marks.first.click()
        expect(marked).to_have_count(n)
    expect(why).to_have_count(0)
    expect(finetune).to_be_enabled()
    ui.in_view_at_every_size(page, finetune, shots=shots, stage="4-marked")

    page.set_viewport_size(SMALLEST)  # the job's progress in view at the smallest size
    finetune.click()
    ui.wait_until(lambda: page.evaluate(BAR_INSIDE) is not None, "the finetuning's progress bar")
    assert page.evaluate(BAR_INSIDE), "the progress bar is outside the window"
    page.screenshot(path=shots / "5-finetuning-1280x720.png")
    ui.wait_for_text(page, "fresh tasks with the shift")
    another = page.get_by_role("button", name="Continue: another task")
    ui.in_view_at_every_size(page, another, shots=shots, stage="6-adapted")
