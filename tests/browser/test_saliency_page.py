"""The saliency overlay of the compare panel, chosen in Chromium: it waits for a demonstration,
then lies over the failed rollout's frames only, beside the untouched counterfactual."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

pytestmark = pytest.mark.browser


def _pixels(locator) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(locator.screenshot())).convert("RGB")).astype(int)


def _choose(page, name: str) -> None:
    page.get_by_role("combobox", name="saliency").click()
    page.get_by_role("option", name=name, exact=True).click()


def test_the_saliency_overlay_lies_over_the_failed_rollout_only(serve_app, ui, shots):
    app = serve_app("nav2d")
    page = ui.open(app.url)
    page.get_by_role("button", name="Load task").click()
    page.get_by_role("button", name="Failed").wait_for()
    _choose(page, "Grad-CAM")  # nothing to explain the actions against yet
    ui.wait_for_text(page, "shown after your demonstration")

    page.get_by_role("button", name="Failed").click()
    page.get_by_role("button", name="Ask the expert").click()
    ui.wait_for_text(page, "Counterfactual found")
    ui.wait_for_text(page, "Grad-CAM: where the failed rollout's frames push")
    frames = ui.frames(page)
    with_heat = _pixels(frames)
    page.screenshot(path=shots / "grad-cam.png")

    _choose(page, "off")
    ui.wait_until(
        lambda: _pixels(frames).shape != with_heat.shape or (_pixels(frames) != with_heat).any(),
        what="the overlay to go",
    )
    plain = _pixels(frames)
    assert plain.shape == with_heat.shape
    changed = (plain != with_heat).any(axis=-1)  # (H, W)
    cols = np.flatnonzero(changed.any(axis=0))
    width = plain.shape[1]
    assert cols.max() < width / 3, "the overlay reaches past the failed rollout's column"
    assert not page.get_by_text("Grad-CAM: where the failed rollout's frames push").is_visible()
    assert app.state.record.diagnosis.result.found
