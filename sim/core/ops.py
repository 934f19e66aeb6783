"""Scene operations: what a variant of a demonstration does to each of its states.

Beside `Edit` (a change of concept values, checked against the values a scene has), an op is
applied to every state of a demonstration alike: set a concept, remove an object, or add one
with a look at a place. `transform(scene, ops)` makes them in order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from sim.core.scene import Obj, Scene


@dataclass(frozen=True)
class SetValue:
    """slot.concept takes `value` (an absent object keeps it for when it is added)."""

    slot: str
    concept: str
    value: str

    def __call__(self, scene: Scene) -> Scene:
        return scene.with_obj(scene.obj(self.slot).with_value(self.concept, self.value))


@dataclass(frozen=True)
class Remove:
    """The object is taken out of the scene (it keeps its look and place, absent)."""

    slot: str

    def __call__(self, scene: Scene) -> Scene:
        return scene.with_obj(replace(scene.obj(self.slot), present=False))


@dataclass(frozen=True)
class Add:
    """The object is put in the scene with `values` ((concept, value) pairs) at `pos`."""

    slot: str
    values: tuple[tuple[str, str], ...]
    pos: tuple[float, ...]

    def __call__(self, scene: Scene) -> Scene:
        return scene.with_obj(Obj(self.slot, True, self.values, self.pos))


Op = SetValue | Remove | Add


def transform(scene: Scene, ops: Sequence[Op]) -> Scene:
    """The scene with each op made, in order."""
    for op in ops:
        scene = op(scene)
    return scene


def stacked(scene: Scene, ops: Sequence[Op]) -> bool:
    """True when an object the ops add shares its place with another present object of the
    (transformed) scene."""
    added = {op.slot for op in ops if isinstance(op, Add)}
    if not added:
        return False

    def place(o) -> tuple[float, ...]:
        return tuple(np.round(o.pos[:2], 6))

    taken = [place(o) for o in scene.objects if o.present and o.slot not in added]
    new = [place(scene.obj(slot)) for slot in sorted(added)]
    # objects the scene already had may share a place (a MuJoCo table and the target it holds)
    return len(set(new)) != len(new) or any(p in taken for p in new)
