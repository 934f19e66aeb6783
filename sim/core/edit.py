"""Edits (Delta phi) and the editor f: `apply(scene, edit) -> Scene`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sim.core.concepts import ABSENT, PRESENCE, PRESENT, ConceptSpace
from sim.core.errors import UserError
from sim.core.scene import Scene


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
        space.check_value(ch.slot, ch.concept, ch.new)
        obj = scene.obj(ch.slot)
        if ch.concept == PRESENCE:
            now = PRESENT if obj.present else ABSENT
            if now != ch.old:
                raise UserError(f"{ch}: slot {ch.slot!r} is {now}, not {ch.old}")
            obj = type(obj)(obj.slot, ch.new == PRESENT, obj.values, obj.pos)
        else:
            if obj.value(ch.concept) != ch.old:
                raise UserError(f"{ch}: {ch.slot}.{ch.concept} is {obj.value(ch.concept)!r}")
            obj = obj.with_value(ch.concept, ch.new)
        scene = scene.with_obj(obj)
    return scene


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
