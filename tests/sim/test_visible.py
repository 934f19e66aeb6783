"""Object masks from the renderer, and the concepts a scene shows."""

import numpy as np

from sim import get_world
from sim.core.visible import shown_slots, slot_masks, visible_concepts


def _slot(world, name):
    return [s.name for s in world.space.slots].index(name)


def test_a_mask_is_exactly_the_pixels_the_object_changes(nav):
    task = nav.test_task("distractor_ti", 0)  # goal and distractor both drawn
    (masks,) = slot_masks(nav, [task.scene])  # (S, H, W)
    frame = nav.render_batch([task.scene])[0]
    for name in ("goal", "distractor"):
        m = masks[_slot(nav, name)]
        assert 4 <= m.sum() <= 60, (name, m.sum())  # a small glyph, not the frame
        assert (frame[m] > 0).any(axis=-1).all()  # drawn on the black arena
    assert not (masks[0] & masks[1]).any()


def test_required_objects_get_their_pixels_by_recolouring():
    world = get_world("doorkey")  # draws key, door and goal whatever their presence flag
    task = world.test_task("object_ti", 0)
    (masks,) = slot_masks(world, [task.scene])
    for name in ("key", "door", "goal"):
        rows, cols = np.nonzero(masks[_slot(world, name)])
        assert len(rows) >= 3, name  # drawn, inside one 3x3 px tile
        assert np.ptp(rows) < 3 and np.ptp(cols) < 3, name
    for name in ("lava0", "lava1", "lava2"):  # no lava in an object shift: nothing drawn
        assert not masks[_slot(world, name)].any()


def test_visible_concepts_and_the_slots_that_show_them(nav):
    plain = nav.test_task("object_ti", 0).scene  # distractor absent
    names = [uc.name for uc in visible_concepts(nav.space, plain)]
    assert names == ["goal.colour", "goal.shape", "distractor.presence"]
    by_name = {uc.name: uc for uc in visible_concepts(nav.space, plain)}
    assert shown_slots(by_name["goal.shape"], plain) == ("goal",)
    assert shown_slots(by_name["distractor.presence"], plain) == ()  # nothing of it is drawn
    busy = nav.test_task("distractor_ti", 0).scene
    shown = {uc.name: shown_slots(uc, busy) for uc in visible_concepts(nav.space, busy)}
    assert shown["distractor.presence"] == shown["distractor.colour"] == ("distractor",)


def test_masks_of_many_scenes_come_in_one_batch(nav):
    scenes = [nav.test_task("distractor_ti", s).scene for s in range(3)]
    masks = slot_masks(nav, scenes)
    assert masks.shape == (3, len(nav.space.slots), 36, 36) and masks.dtype == np.bool_
    assert slot_masks(nav, []).shape == (0, len(nav.space.slots), 36, 36)
