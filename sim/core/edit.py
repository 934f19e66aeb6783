"""Edits (Delta phi) and the editor f: `apply(scene, edit) -> Scene`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sim.core.concepts import ABSENT, PRESENCE, PRESENT, ConceptSpace
from sim.core.errors import UserError
from sim.core.scene import Obj, Scene


@dataclass(frozen=True, order=True)
class Change:
    """One atomic change: slot.concept goes from `old` to `new` (concept may be "presence")."""

    slot: str
    concept: str
    old: str
    new: str

    def to_dict(self) -> dict[str, str]:
        return {"slot": self.slot, "concept": self.concept, "from": self.old, "to": self.new}

    def __str__(self) -> str:
        return f"{self.slot}.{self.concept}: {self.old} -> {self.new}"


@dataclass(frozen=True)
class Edit:
    """A set of atomic changes, at most one per (slot, concept). Size = number of changes."""

    changes: frozenset[Change]

    def __post_init__(self) -> None:
        if len(self.changes) < 2:
            return
        keys = [(c.slot, c.concept) for c in self.changes]
        if len(keys) != len(set(keys)):
            raise UserError(f"an edit changes each (slot, concept) at most once: {sorted(keys)}")

    @classmethod
    def of(cls, *changes: Change) -> Edit:
        return cls(frozenset(changes))

    @property
    def size(self) -> int:
        return len(self.changes)

    @property
    def ordered(self) -> tuple[Change, ...]:
        return tuple(sorted(self.changes))

    @property
    def is_presence(self) -> bool:
        return any(c.concept == PRESENCE for c in self.changes)

    def to_list(self) -> list[dict[str, str]]:
        return [c.to_dict() for c in self.ordered]

    @classmethod
    def from_list(cls, items: list[dict[str, Any]]) -> Edit:
        try:
            return cls.of(*(Change(d["slot"], d["concept"], d["from"], d["to"]) for d in items))
        except (KeyError, TypeError) as e:
            raise UserError(
                f"malformed edit {items!r}: each change needs slot, concept, from, to"
            ) from e

    def __str__(self) -> str:
        return "; ".join(str(c) for c in self.ordered) or "(no change)"


EMPTY = Edit(frozenset())


def apply(space: ConceptSpace, scene: Scene, edit: Edit) -> Scene:
    """The editor f: the scene with every change of `edit` made. Checks each change's `old`."""
    for ch in edit.ordered:
        scene = scene.with_obj(_changed(space, scene.obj(ch.slot), ch))
    return scene


def _changed(space: ConceptSpace, obj: Obj, ch: Change) -> Obj:
    """obj with one change of its slot made (UserError unless `ch.old` is what obj holds)."""
    space.check_value(ch.slot, ch.concept, ch.new)
    if ch.concept == PRESENCE:
        now = PRESENT if obj.present else ABSENT
        if now != ch.old:
            raise UserError(f"{ch}: slot {ch.slot!r} is {now}, not {ch.old}")
        return type(obj)(obj.slot, ch.new == PRESENT, obj.values, obj.pos)
    if obj.value(ch.concept) != ch.old:
        raise UserError(f"{ch}: {ch.slot}.{ch.concept} is {obj.value(ch.concept)!r}")
    return obj.with_value(ch.concept, ch.new)


def apply_many(space: ConceptSpace, scene: Scene, edits: Sequence[Edit]) -> list[Scene]:
    """[apply(space, scene, e) for e in edits], the same scenes: each slot's changes are made
    once per batch (an edit's objects are shared with the other edits that change that slot
    the same way, and the unchanged ones are the scene's own)."""
    where = {o.slot: i for i, o in enumerate(scene.objects)}
    made: dict[tuple[Change, ...], Obj] = {}  # one slot's changes, in order -> its object

    def slot_after(changes: tuple[Change, ...]) -> Obj:
        obj = made.get(changes)
        if obj is None:
            before = slot_after(changes[:-1]) if len(changes) > 1 else scene.obj(changes[0].slot)
            obj = made[changes] = _changed(space, before, changes[-1])
        return obj

    out = []
    for edit in edits:
        objects = list(scene.objects)
        if len(edit.changes) == 1:
            (ch,) = edit.changes
            objects[where[ch.slot]] = slot_after((ch,))
        else:
            by_slot: dict[str, list[Change]] = {}
            for ch in edit.ordered:
                by_slot.setdefault(ch.slot, []).append(ch)
            for slot, changes in by_slot.items():
                objects[where[slot]] = slot_after(tuple(changes))
        out.append(Scene(scene.world, tuple(objects), scene.agent))
    return out


def single_changes(space: ConceptSpace, scene: Scene) -> tuple[list[Change], list[Change]]:
    """All atomic changes of `scene`: (presence changes, instantiation changes).

    Instantiation changes are offered for absent slots too (they matter combined with adding
    the object); `effective` tells whether an edit changes anything visible.
    """
    presence: list[Change] = []
    values: list[Change] = []
    for s in space.slots:
        obj = scene.obj(s.name)
        if s.optional:
            old = PRESENT if obj.present else ABSENT
            presence.append(Change(s.name, PRESENCE, old, ABSENT if obj.present else PRESENT))
        for c in s.concepts:
            cur = obj.value(c.name)
            values.extend(Change(s.name, c.name, cur, v) for v in c.values if v != cur)
    return presence, values


def effective(scene: Scene, edit: Edit) -> bool:
    """False when the edit changes the appearance of a slot that is absent after the edit."""
    adds = {c.slot for c in edit.changes if c.concept == PRESENCE and c.new == PRESENT}
    removes = {c.slot for c in edit.changes if c.concept == PRESENCE and c.new == ABSENT}
    for c in edit.changes:
        if c.concept == PRESENCE:
            continue
        if c.slot in removes or (not scene.obj(c.slot).present and c.slot not in adds):
            return False
    return True
