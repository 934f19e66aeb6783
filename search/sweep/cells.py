"""Sweep cells: which edit of a scene each (slot, concept, value) stands for, and the tasks a
sweep runs on."""

from __future__ import annotations

from sim.core import (
    ABSENT,
    PRESENCE,
    PRESENT,
    Change,
    ConceptSpace,
    Edit,
    Scene,
    Task,
    World,
    effective,
)

CellKey = tuple[str, str, str]  # (slot, concept, value)
PairKey = tuple[CellKey, CellKey]


def cell_keys(space: ConceptSpace) -> list[CellKey]:
    """Every (slot, concept, value) of the space, in its order: presence first for optional
    slots."""
    keys: list[CellKey] = []
    for s in space.slots:
        if s.optional:
            keys += [(s.name, PRESENCE, PRESENT), (s.name, PRESENCE, ABSENT)]
        keys += [(s.name, c.name, v) for c in s.concepts for v in c.values]
    return keys


def cell_edit(scene: Scene, key: CellKey) -> Edit | None:
    """The edit of `scene` that cell `key` stands for, or None where it changes nothing."""
    slot, concept, value = key
    obj = scene.obj(slot)
    if concept == PRESENCE:
        now = PRESENT if obj.present else ABSENT
        return None if value == now else Edit.of(Change(slot, PRESENCE, now, value))
    cur = obj.value(concept)
    if obj.present:
        return None if value == cur else Edit.of(Change(slot, concept, cur, value))
    add = Change(slot, PRESENCE, ABSENT, PRESENT)
    return Edit.of(add) if value == cur else Edit.of(add, Change(slot, concept, cur, value))


def pair_edit(scene: Scene, pair: PairKey) -> Edit | None:
    """Both cells' edits at once, or None when either does nothing, they clash, or together
    they are just one of them."""
    a, b = (cell_edit(scene, k) for k in pair)
    if a is None or b is None:
        return None
    changes = a.changes | b.changes
    if len({(c.slot, c.concept) for c in changes}) < len(changes):
        return None
    edit = Edit(frozenset(changes))
    if edit in (a, b) or not effective(scene, edit):
        return None
    return edit


def added_slot(edit: Edit) -> str | None:
    """The slot an edit adds (an edit adds at most one in a single cell), or None."""
    adds = [c.slot for c in edit.ordered if c.concept == PRESENCE and c.new == PRESENT]
    return adds[0] if len(adds) == 1 else None


def key_edit(scene: Scene, key: CellKey | PairKey) -> Edit | None:
    return pair_edit(scene, key) if isinstance(key[0], tuple) else cell_edit(scene, key)  # type: ignore[arg-type]


def label(key: CellKey | PairKey) -> str:
    """A cell as slot.concept=value; a pair as two of them joined by " + "."""
    if isinstance(key[0], tuple):
        return " + ".join(label(k) for k in key)  # type: ignore[arg-type]
    slot, concept, value = key  # type: ignore[misc]
    return f"{slot}.{concept}={value}"


def task_of(world: World, seed: int) -> Task:
    """The sweep's task of `seed`: a Benchmark's training task, else the world's task for the
    scene it samples with that seed."""
    if world.benchmark:
        return world.train_task(seed)  # type: ignore[attr-defined]
    task = world.task_for(world.sample_scene(seed))
    return Task(task.world, task.scene, task.reward, task.shift, seed, task.cause)


def sweep_tasks(world: World, n: int, seed: int = 0) -> list[Task]:
    """The tasks of seeds seed, seed + 1, ..., seed + n - 1."""
    return [task_of(world, seed + i) for i in range(n)]
