"""What a person can point at in a frame: the concepts a scene shows and each object's pixels.

visible_concepts(space, scene)   the user concepts of the scene: the looks of objects that are
                                 there, and the presence of every optional kind
shown_slots(concept, scene)      the slots whose pixels show a user concept
slot_masks(world, scenes)        bool (B, S, H, W): each present slot's pixels in each scene,
                                 from the world's own renderer

Masks come from the renderer itself, never from a world's geometry: a present slot's pixels
are those that change when it is removed. A renderer that draws a required object whatever
its presence flag (DoorKey's key, door and goal) shows no change; for such a slot the mask is
every pixel that changes under any single change of its concepts (recolouring it), which are
its pixels. An absent object has no pixels: nothing of it is drawn, so no map can point at it.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from sim.core.concepts import ConceptSpace, UserConcept
from sim.core.edit import Edit, single_changes
from sim.core.scene import Scene

if TYPE_CHECKING:
    from sim.core.world import World


def visible_concepts(space: ConceptSpace, scene: Scene) -> tuple[UserConcept, ...]:
    """The concepts a person can point at in `scene`, in the space's order: the looks of the
    objects that are there, and the presence of any optional kind (adding an object is always
    visible). The looks of an object that is not in the scene are not something anyone names."""
    shown = (uc.in_scene(scene) for uc in space.user_concepts())
    return tuple(uc for uc in shown if uc is not None)


def shown_slots(concept: UserConcept, scene: Scene) -> tuple[str, ...]:
    """The slots whose pixels show `concept` in `scene`: its member slots that are present
    (none for the presence of a kind with no object in the scene). Concepts of one object (its
    looks, its presence) share its slots."""
    slots = tuple(dict.fromkeys(s for s, _ in concept.members))
    return tuple(s for s in slots if scene.obj(s).present)


def slot_masks(world: World, scenes: list[Scene]) -> np.ndarray:
    """bool (B, S, H, W): the pixels of slot s (the space's order) in scene b; all False for a
    slot absent from that scene, or present but not drawn (a key the agent carries).

    One batched render of every scene with each present slot removed; slots the renderer draws
    whatever their flag then get the union of the pixels each single value change of theirs
    alters (one more batched render).
    """
    slots = world.space.slots
    b, s = len(scenes), len(slots)
    h, w, _ = world.obs_shape
    masks = np.zeros((b, s, h, w), bool)
    shown = [
        (i, j)
        for i, sc in enumerate(scenes)
        for j, sl in enumerate(slots)
        if sc.obj(sl.name).present
    ]
    if not shown:
        return masks
    base = world.render_batch(scenes)  # (B, H, W, 3)
    removed = [
        scenes[i].with_obj(replace(scenes[i].obj(slots[j].name), present=False)) for i, j in shown
    ]
    frames = world.render_batch(removed)  # (N, H, W, 3)
    rows = [i for i, _ in shown]
    for (i, j), px in zip(shown, (frames != base[rows]).any(axis=-1), strict=True):
        masks[i, j] = px
    edited, owners = [], []
    for i, j in shown:
        if masks[i, j].any():
            continue
        _, values = single_changes(world.space, scenes[i])
        for ch in values:
            if ch.slot == slots[j].name:
                edited.append(world.apply(scenes[i], Edit.of(ch)))
                owners.append((i, j))
    if edited:
        changed = (world.render_batch(edited) != base[[i for i, _ in owners]]).any(axis=-1)
        for (i, j), px in zip(owners, changed, strict=True):  # px (H, W)
            masks[i, j] |= px
    return masks
