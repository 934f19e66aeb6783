"""What the page draws on a pick-and-place world's frames: where the action picked and placed."""

from __future__ import annotations

import numpy as np

from dfa_viz.app.frames import mark_pick_place
from sim import get_world


def test_the_pick_and_place_points_are_drawn_where_the_action_took_and_left_the_object():
    world = get_world("tabletop")
    task = world.test_task("object_ti", 0)
    demo = world.demonstrate(task)
    frame = demo.observations[0]
    marked = mark_pick_place(world, frame, demo.actions[0], (255, 0, 0))
    assert marked.shape == frame.shape and marked.dtype == np.uint8
    x0, x1, y0, y1 = world.image_extent
    h, w = frame.shape[:2]
    a = np.asarray(demo.actions[0], float).reshape(-1)
    for (x, y), colour in (((a[0], a[1]), (255, 0, 0)), ((a[2], a[3]), (255, 255, 255))):
        px, py = int((x - x0) / (x1 - x0) * w), int((y1 - y) / (y1 - y0) * h)
        assert tuple(marked[py, px]) == colour, (px, py, marked[py, px])
    changed = np.abs(marked.astype(int) - frame).sum(axis=-1) > 0
    assert 0 < changed.mean() < 0.2  # two points and a line, not the whole frame
