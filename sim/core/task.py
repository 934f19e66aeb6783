"""Tasks: a scene plus the user's intended reward R' as data; the five shift kinds."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from sim.core.concepts import ABSENT, PRESENCE, PRESENT, ConceptSpace
from sim.core.errors import UserError
from sim.core.scene import Scene

SHIFTS = ("object_ti", "object_tr", "distractor_ti", "distractor_tr", "other")
TRAIN = "train"
LAYOUTS = ("task", "train")  # where fresh tasks put the objects (World.fresh_tasks)


MAX_SEED = 2**31 - 1


def check_seed(seed: int, name: str = "seed") -> int:
    """A seed is an integer from 0 to MAX_SEED."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise UserError(f"{name} must be an integer from 0 to {MAX_SEED}, not {seed}")
    return seed


def check_shift(shift: str) -> str:
    if shift not in SHIFTS:
        raise UserError(f"unknown shift {shift!r}; accepted: {', '.join(SHIFTS)}")
    return shift


def check_layouts(layouts: str) -> str:
    if layouts not in LAYOUTS:
        raise UserError(f"unknown layouts {layouts!r}; accepted: {', '.join(LAYOUTS)}")
    return layouts


@dataclass(frozen=True)
class Reward:
    """The user's intended reward R', as data.

    instruction: what the user wants, in words.
    relevant: (slot, concept) pairs that matter to R' (concept may be "presence").
    allowed: for each (slot, concept) that R' leaves open, the instantiations that satisfy it,
        as (slot, concept, values) triples; fresh tasks from R' draw from these.
    success: name of the world's success predicate (e.g. "reach_goal").
    avoid: slots the agent must keep clear of (the world's predicate reads it).
    """

    instruction: str
    relevant: frozenset[tuple[str, str]]
    allowed: tuple[tuple[str, str, tuple[str, ...]], ...] = ()
    success: str = "reach_goal"
    avoid: tuple[str, ...] = ()

    def is_relevant(self, slot: str, concept: str) -> bool:
        return (slot, concept) in self.relevant

    def allowed_values(self, slot: str, concept: str) -> tuple[str, ...] | None:
        for s, c, vals in self.allowed:
            if (s, c) == (slot, concept):
                return vals
        return None

    def to_dict(self) -> dict[str, Any]:
        return {
            "instruction": self.instruction,
            "relevant": sorted([list(p) for p in self.relevant]),
            "allowed": [[s, c, list(v)] for s, c, v in self.allowed],
            "success": self.success,
            "avoid": list(self.avoid),
        }


@dataclass(frozen=True)
class Task:
    """A test (or training) task: its initial scene, R', the shift that made it, and its seed.

    cause: the (slot, concept) the shift generator changed ("presence" for distractors);
    None for the training task and for `other` (the cause is outside the concept space).
    """

    world: str
    scene: Scene
    reward: Reward
    shift: str
    seed: int
    cause: tuple[str, str] | None = None

    def with_scene(self, scene: Scene) -> Task:
        return replace(self, scene=scene)

    def to_dict(self) -> dict[str, Any]:
        return {
            "world": self.world,
            "shift": self.shift,
            "seed": self.seed,
            "cause": list(self.cause) if self.cause else None,
            "scene": self.scene.to_dict(),
            "reward": self.reward.to_dict(),
        }


def draw_from_reward(scene: Scene, reward: Reward, rng) -> Scene:
    """`scene` with every (slot, concept) R' leaves open drawn from its allowed values, in the
    order of `reward.allowed` (one rng.integers call each); positions are left as they are."""
    for slot, concept, values in reward.allowed:
        v = str(values[rng.integers(len(values))])
        o = scene.obj(slot)
        scene = scene.with_obj(
            replace(o, present=v == PRESENT) if concept == PRESENCE else o.with_value(concept, v)
        )
    return scene


def carrying_shift(space: ConceptSpace, task: Task) -> Reward:
    """R' narrowed so that every task drawn from it keeps the test task's shift (its other open
    concepts stay open): the cause at the value the shift gave it, which R' accepts and
    training never showed; for a distractor, every object of its kind present (or absent) and
    looking as in the test task. Tasks without a cause (`other`, training) keep R'."""
    if task.cause is None:
        return task.reward
    slot, concept = task.cause
    fixed: dict[tuple[str, str], tuple[str, ...]] = {}
    if concept == PRESENCE:
        kind = space.slot(slot).kind
        for s in space.slots:
            if s.kind != kind:
                continue
            o = task.scene.obj(s.name)
            fixed[(s.name, PRESENCE)] = (PRESENT if o.present else ABSENT,)
            if o.present:
                fixed.update({(s.name, c.name): (o.value(c.name),) for c in s.concepts})
    else:
        fixed[(slot, concept)] = (task.scene.obj(slot).value(concept),)
    allowed = [(s, c, fixed.pop((s, c), vals)) for s, c, vals in task.reward.allowed]
    allowed += [(s, c, vals) for (s, c), vals in fixed.items()]
    return replace(task.reward, allowed=tuple(allowed))
