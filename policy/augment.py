"""Augmentation: re-render the demonstration over every allowed instantiation of its TI concepts."""

from __future__ import annotations

import itertools
import math

import numpy as np

from sim.core import ABSENT, PRESENCE, PRESENT, Feedback, Obj, Scene, Task, Trajectory, World

MAX_AUGMENTED = 100  # default cap on augmented demonstrations (drawn evenly when exceeded)


def _variants(world: World, task: Task, demo: Trajectory, feedback: Feedback):
    """Per TI label, the scene transforms it allows: functions Scene -> Scene."""
    per_label = []
    for lab in feedback.irrelevant:
        slot = world.space.slot(lab.slot)
        obj = task.scene.obj(lab.slot)
        if lab.concept != PRESENCE:
            values = lab.acceptable or slot.concept(lab.concept).values
            per_label.append([("set", lab.slot, lab.concept, v) for v in values])
            continue
        options = []
        if ABSENT in (lab.acceptable or (ABSENT,)) and obj.present:
            options.append(("remove", lab.slot))
        if PRESENT in (lab.acceptable or (PRESENT,)):
            looks = itertools.product(*(c.values for c in slot.concepts))
            places = world.placements(task, lab.slot, demo)
            names = [c.name for c in slot.concepts]
            options += [
                ("add", lab.slot, tuple(zip(names, look, strict=True)), pos)
                for look in looks
                for pos in places
            ]
        per_label.append(options)
    return per_label


def transform(scene: Scene, ops) -> Scene:
    """The scene with each op made: ("set", slot, concept, value), ("remove", slot) or
    ("add", slot, values, pos). The same ops are applied to every state of a demonstration."""
    for op in ops:
        o = scene.obj(op[1])
        if op[0] == "set":
            o = o.with_value(op[2], op[3])
        elif op[0] == "remove":
            o = Obj(o.slot, False, o.values, o.pos)
        else:  # add
            o = Obj(o.slot, True, op[2], op[3])
        scene = scene.with_obj(o)
    return scene


ENUMERATE_BELOW = 50_000  # above this many combinations, draw them instead of listing all


def _useful(scene: Scene, ops) -> bool:
    """The ops change the scene and do not stack two added objects on one place."""
    added = [op[3] for op in ops if op[0] == "add"]
    return len(added) == len(set(added)) and transform(scene, ops) != scene


def _combinations(scene: Scene, per_label: list, max_augmented: int, seed: int) -> list:
    """At most `max_augmented` useful combinations (one option per label), drawn evenly."""
    sizes = [len(options) for options in per_label]
    total = math.prod(sizes)
    rng = np.random.default_rng(seed)
    if total <= ENUMERATE_BELOW:
        combos = [c for c in itertools.product(*per_label) if _useful(scene, c)]
        if len(combos) > max_augmented:
            pick = rng.choice(len(combos), max_augmented, replace=False)
            combos = [combos[i] for i in sorted(pick)]
        return combos
    chosen: dict[int, tuple] = {}
    seen: set[int] = set()
    for _ in range(50 * max_augmented):  # large products: draw flat indices, decode each
        i = int(rng.integers(total))
        if i in seen:
            continue
        seen.add(i)
        combo = tuple(
            opts[j] for opts, j in zip(per_label, np.unravel_index(i, sizes), strict=True)
        )
        if _useful(scene, combo):
            chosen[i] = combo
            if len(chosen) == max_augmented:
                break
    return [chosen[i] for i in sorted(chosen)]


def augment(
    world: World,
    task: Task,
    demo: Trajectory,
    feedback: Feedback,
    *,
    max_augmented: int = MAX_AUGMENTED,
    seed: int = 0,
) -> list[Trajectory]:
    """The demonstration re-rendered for every combination the TI labels allow.

    Each augmented trajectory keeps the demonstrated actions; its states are the demonstrated
    states with the concept edited (or the distractor added at a placement off the path, or
    removed). Combinations identical to the demonstration, or stacking two added objects on
    one place, are skipped. When there are more than `max_augmented`, that many are drawn
    without replacement (seeded); very large products are sampled without being listed.
    """
    per_label = _variants(world, task, demo, feedback)
    if not per_label:
        return []
    combos = _combinations(task.scene, per_label, max_augmented, seed)
    out = []
    for ops in combos:
        scenes = tuple(transform(s, ops) for s in demo.scenes)
        obs = world.render_batch(scenes)  # (T+1, H, W, 3)
        out.append(Trajectory(scenes, obs, demo.actions, demo.success))
    return out
