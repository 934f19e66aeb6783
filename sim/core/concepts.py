"""The concept space: slots x concepts x instantiations, plus presence, and its one-hot Phi."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.core.errors import UserError
from sim.core.scene import Obj, Scene

PRESENCE = "presence"
SHORT_LIST = 6  # value lists up to this long are written out in full
PRESENT, ABSENT = "present", "absent"


@dataclass(frozen=True)
class Concept:
    """One visual concept of a slot (e.g. colour) and its finite instantiations."""

    name: str
    values: tuple[str, ...]

    def index(self, value: str) -> int:
        if value not in self.values:
            raise UserError(f"unknown {self.name} {value!r}; accepted: {', '.join(self.values)}")
        return self.values.index(value)


@dataclass(frozen=True)
class Slot:
    """An object slot. `optional` slots can be absent, so presence is an editable concept.

    kind: the kind of object the slot holds; slots of one kind are interchangeable to a person
    (DoorKey's lava0..lava2 are all "lava"): "the lava does not matter" is said of the kind.
    Defaults to the slot's name.
    """

    name: str
    concepts: tuple[Concept, ...]
    optional: bool = False
    kind: str = ""

    def __post_init__(self) -> None:
        if not self.kind:
            object.__setattr__(self, "kind", self.name)

    @property
    def concept_names(self) -> tuple[str, ...]:
        """Presence first (for optional slots), then every concept, in order."""
        return ((PRESENCE,) if self.optional else ()) + tuple(c.name for c in self.concepts)

    def concept(self, name: str) -> Concept:
        for c in self.concepts:
            if c.name == name:
                return c
        names = [c.name for c in self.concepts] + ([PRESENCE] if self.optional else [])
        raise UserError(
            f"unknown concept {name!r} for slot {self.name!r}; accepted: {', '.join(names)}"
        )

    @property
    def width(self) -> int:
        return sum(len(c.values) for c in self.concepts)


@dataclass(frozen=True)
class UserConcept:
    """One concept as a person names it, and the (slot, concept) pairs it covers."""

    name: str
    """E.g. "goal.colour" or "lava.presence" (kind.concept)."""
    members: tuple[tuple[str, str], ...]
    """The (slot, concept) pairs of the concept space it covers (concept may be "presence")."""

    @property
    def is_presence(self) -> bool:
        return self.members[0][1] == PRESENCE

    def in_scene(self, scene: Scene) -> UserConcept | None:
        """The part a scene shows: presence, and the looks of the slots present in it."""
        members = tuple((s, c) for s, c in self.members if c == PRESENCE or scene.obj(s).present)
        return UserConcept(self.name, members) if members else None


@dataclass(frozen=True)
class ConceptSpace:
    """Phi's codomain: the ordered slots of a world.

    Phi(scene) concatenates, slot by slot, one one-hot vector per concept; an absent slot is all
    zeros. Positions are not part of Phi (they are carried by the scene, outside the space).
    """

    slots: tuple[Slot, ...]

    def slot(self, name: str) -> Slot:
        for s in self.slots:
            if s.name == name:
                return s
        raise UserError(f"unknown slot {name!r}; accepted: {', '.join(s.name for s in self.slots)}")

    @property
    def dim(self) -> int:
        return sum(s.width for s in self.slots)

    def offsets(self) -> dict[tuple[str, str], int]:
        """Start index in Phi of each (slot, concept) one-hot."""
        out, i = {}, 0
        for s in self.slots:
            for c in s.concepts:
                out[(s.name, c.name)] = i
                i += len(c.values)
        return out

    def encode(self, scene: Scene) -> np.ndarray:
        """Phi(scene) -> uint8 (D,) one-hot per (slot, concept); zeros for absent slots."""
        phi = np.zeros(self.dim, dtype=np.uint8)
        offsets = self.offsets()
        for s in self.slots:
            obj = scene.obj(s.name)
            if not obj.present:
                continue
            for c in s.concepts:
                phi[offsets[(s.name, c.name)] + c.index(obj.value(c.name))] = 1
        return phi

    def decode(self, phi: np.ndarray, like: Scene) -> Scene:
        """Phi^-1 on concepts: the scene `like` with every slot's presence and values from phi.

        Absent slots keep the values they had in `like` (their latent appearance), so
        decode(encode(s), s) == s exactly.
        """
        phi = np.asarray(phi)
        assert phi.shape == (self.dim,), f"phi must have shape ({self.dim},), got {phi.shape}"
        offsets = self.offsets()
        objs = []
        for s in self.slots:
            obj = like.obj(s.name)
            block = [
                phi[offsets[(s.name, c.name)] : offsets[(s.name, c.name)] + len(c.values)]
                for c in s.concepts
            ]
            present = bool(block and block[0].any())
            if not present and not s.optional:
                raise UserError(f"phi marks slot {s.name!r} absent, but it cannot be absent")
            if present:
                values = []
                for c, b in zip(s.concepts, block, strict=True):
                    if b.sum() != 1:
                        raise UserError(f"phi for {s.name}.{c.name} is not one-hot: {b.tolist()}")
                    values.append((c.name, c.values[int(np.argmax(b))]))
                obj = Obj(s.name, True, tuple(values), obj.pos)
            else:
                obj = Obj(s.name, False, obj.values, obj.pos)
            objs.append(obj)
        return Scene(like.world, tuple(objs), like.agent)

    def values(self, slot: str, concept: str) -> tuple[str, ...]:
        """Every instantiation of slot.concept; presence is (present, absent)."""
        s = self.slot(slot)
        if concept == PRESENCE:
            if not s.optional:
                raise UserError(f"slot {slot!r} is always present; its presence cannot change")
            return (PRESENT, ABSENT)
        return s.concept(concept).values

    def accepted(self, reward, slot: str, concept: str) -> tuple[str, ...]:
        """The instantiations of slot.concept that the intended reward R' (a sim.core.Reward)
        accepts: those it allows when it names the concept, else every one."""
        every = self.values(slot, concept)
        allowed = reward.allowed_values(slot, concept)
        return every if allowed is None else tuple(v for v in every if v in allowed)

    def describe(self, slot: str, concept: str, chosen: Sequence[str]) -> str:
        """Some instantiations of slot.concept in words a person reads at a glance: "all 81
        colours", "all colours but red, dark red", "present or absent", or the list itself
        when it is short (at most SHORT_LIST values), else its first few and a count."""
        every = self.values(slot, concept)
        picked = [v for v in every if v in set(chosen)]
        if concept == PRESENCE:
            return " or ".join(picked) if len(picked) != 1 else f"only {picked[0]}"
        noun = concept if concept.endswith("s") else f"{concept}s"
        missing = [v for v in every if v not in set(chosen)]
        if not missing:
            return f"all {len(every)} {noun}" if len(every) > 2 else " or ".join(every)
        if not picked:
            return f"no {noun}"
        if len(missing) <= SHORT_LIST < len(picked):
            return f"all {noun} but {', '.join(missing)}"
        if len(picked) <= SHORT_LIST:
            return ", ".join(picked)
        return f"{len(picked)} of {len(every)} {noun}: {', '.join(picked[:SHORT_LIST])}, …"

    def user_concepts(self) -> tuple[UserConcept, ...]:
        """Every concept as a person names it ("goal.colour", "lava.presence"), in the order
        of the space: one per (kind, concept), covering that concept of every slot of the kind."""
        groups: dict[str, list[tuple[str, str]]] = {}
        for s in self.slots:
            for concept in s.concept_names:
                groups.setdefault(f"{s.kind}.{concept}", []).append((s.name, concept))
        return tuple(UserConcept(name, tuple(members)) for name, members in groups.items())

    def user_concept(self, slot: str, concept: str) -> UserConcept:
        """The user concept (slot, concept) belongs to."""
        name = f"{self.slot(slot).kind}.{concept}"
        return next(uc for uc in self.user_concepts() if uc.name == name)

    def check_value(self, slot: str, concept: str, value: str) -> None:
        """Raise a UserError unless `value` is an instantiation of slot.concept."""
        s = self.slot(slot)
        if concept == PRESENCE:
            if not s.optional:
                raise UserError(f"slot {slot!r} is always present; its presence cannot change")
            if value not in (PRESENT, ABSENT):
                raise UserError(f"presence is {PRESENT!r} or {ABSENT!r}, not {value!r}")
            return
        s.concept(concept).index(value)
