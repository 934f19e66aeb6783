"""Clicks on a MuJoCo world's frames for tests: where a slot is drawn, read from the frames
themselves (sim.core.visible.slot_masks), and a click on the middle of it."""

from __future__ import annotations

import numpy as np

from sim.core.visible import slot_masks


def drawn(world, scene, slot: str) -> np.ndarray:
    """bool (H, W): the pixels of the frame where `slot` is drawn (sim.core.visible's)."""
    names = [s.name for s in world.space.slots]
    return slot_masks(world, [scene])[0, names.index(slot)]


def click_on(world, mask: np.ndarray, view: int) -> tuple[float, float]:
    """(u, v) of the middle of the mask's pixels in view `view` of the frame."""
    size = world.size_px
    rows, cols = np.nonzero(mask[:, view * size : (view + 1) * size])
    assert len(rows) >= 3, f"the slot is not drawn in view {view}"
    h, w = mask.shape
    return (view * size + cols.mean() + 0.5) / w, (rows.mean() + 0.5) / h
