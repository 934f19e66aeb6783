"""What the evaluation keeps from finetuning: held-out layouts and held-out accepted values.

A policy finetuned on variants of training layouts and scored on fresh tasks drawn from those
same layouts is scored on scenes it was finetuned on. So each test task's evaluation is planned
before anything is finetuned (`plan`), the same for every condition and budget of one seed:

- layouts: a seeded share (HELD_LAYOUTS) of the base policy's training layouts, never the test
  task's own (the demonstration starts there), is kept for evaluation. No finetuning trajectory
  starts from one of them: variants are made only from training demonstrations on the other
  layouts (`Holdout.sources`), and fresh tasks are kept only on layouts no finetuning source
  has (`Holdout.fresh_layout`). A layout is where the agent and the objects every scene has
  (the world's non-optional slots) stand; optional objects (distractors) may go anywhere.
- values: for a task-irrelevant cause, the values R' accepts for it that neither the test task
  nor training shows are split in two, seeded: half (rounded down) never appear in any variant
  (`Holdout.restrict`) and are what the fresh tasks carrying the shift show instead of the test
  task's value. A distractor's cause is its presence, and the values held out are those of the
  look concept of its kind with the most values (nav2d: the distractor's colour). With fewer
  than MIN_VALUES such values (DoorKey's two lava colours; a task-relevant cause, which R' fixes
  at the test task's value) nothing is held out: the fresh tasks carrying the shift show the
  test task's value, which the demonstration shows too (`Holdout.values` is then empty, and
  reports say so).

The replayed training demonstrations (the base policy's own data, in training looks) are not
finetuning trajectories here: they start from every training layout, held-out ones too.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.core import PRESENCE, Scene, Task, Trajectory, World

HELD_LAYOUTS = 1 / 3  # share of the training layouts (test task's excluded) kept for evaluation
MIN_VALUES = 2  # unseen accepted values a concept needs before half of them are held out

Layout = tuple[tuple[float, ...], ...]


def layout_of(world: World, scene: Scene) -> Layout:
    """Where the agent and every object of a non-optional slot stand."""
    fixed = tuple(tuple(scene.obj(s.name).pos) for s in world.space.slots if not s.optional)
    return (tuple(scene.agent[:2]), *fixed)


@dataclass(frozen=True)
class Holdout:
    """What one test task's evaluation keeps from its finetuning."""

    used: frozenset[Layout]
    """Layouts finetuning trajectories may start from (the test task's and the training
    layouts not held out); a fresh task on one of them is not drawn."""
    held_layouts: int
    """How many training layouts are held out for evaluation."""
    values: tuple[tuple[str, str, tuple[str, ...]], ...] = ()
    """(slot, concept, values) no variant may show, which the fresh tasks carrying the shift
    show instead of the test task's value; () when nothing is held out."""

    def keeps(self, world: World, scene: Scene) -> bool:
        """True when a finetuning trajectory may start from `scene`'s layout."""
        return layout_of(world, scene) in self.used

    def fresh_layout(self, world: World, scene: Scene) -> bool:
        """True when no finetuning trajectory may start from `scene`'s layout."""
        return layout_of(world, scene) not in self.used

    def sources(self, world: World, known: Sequence[Trajectory]) -> list[Trajectory]:
        """The training demonstrations variants may be made from: those on a layout not held
        out."""
        return [d for d in known if self.keeps(world, d.scenes[0])]

    def held(self, slot: str, concept: str) -> tuple[str, ...]:
        """The values of slot.concept held out ((): none)."""
        return next((v for s, c, v in self.values if (s, c) == (slot, concept)), ())

    def restrict(self, what):
        """An Irrelevant (policy.variants) whose variants never show a held-out value."""
        from dataclasses import replace

        return replace(what, held=self.values)

    @property
    def held_values(self) -> tuple[str, ...]:
        """The held-out values (the same for every slot they are held for)."""
        return self.values[0][2] if self.values else ()

    def shown(self, task: Task) -> list[Task]:
        """The test task as many times as there are held-out values, each showing one of them
        where the test task shows its cause ([task] when nothing is held out): what fresh tasks
        carrying the shift are drawn from."""
        if not self.values:
            return [task]
        out = []
        for v in self.held_values:
            scene = task.scene
            for slot, concept, _ in self.values:
                o = scene.obj(slot)
                if o.present:
                    scene = scene.with_obj(o.with_value(concept, v))
            out.append(task.with_scene(scene))
        return out


@functools.lru_cache(maxsize=8)
def _training_scenes(world: World) -> tuple[Scene, ...]:
    from policy.train import training_tasks

    return tuple(t.scene for t in training_tasks(world))


def _held_concepts(world: World, task: Task) -> list[tuple[str, str]]:
    """The (slot, concept) pairs whose values may be held out for `task`'s cause."""
    if task.cause is None:
        return []
    slot, concept = task.cause
    if concept != PRESENCE:
        return [(slot, concept)]
    space = world.space
    kind = space.slot(slot).kind
    looks = space.slot(slot).concepts
    if not looks:
        return []
    widest = max(looks, key=lambda c: len(c.values)).name  # max keeps the first of a tie
    return [(s.name, widest) for s in space.slots if s.kind == kind]


def plan(world: World, task: Task, seed: int) -> Holdout:
    """The held-out layouts and values of `task`'s evaluation for run seed `seed`."""
    from policy.variants import stable_int

    rng = np.random.default_rng([seed, stable_int("holdout", world.name, task.shift, task.seed)])
    train = _training_scenes(world)
    own = layout_of(world, task.scene)
    layouts = list(dict.fromkeys(layout_of(world, s) for s in train if layout_of(world, s) != own))
    n_held = math.ceil(HELD_LAYOUTS * len(layouts)) if len(layouts) > 1 else 0
    held = {layouts[i] for i in rng.permutation(len(layouts))[:n_held]}
    used = frozenset({own, *(lay for lay in layouts if lay not in held)})
    pairs = _held_concepts(world, task)
    if not pairs:
        return Holdout(used, n_held)
    seen = {task.scene.obj(s).value(c) for s, c in pairs if task.scene.obj(s).present}
    if task.cause[1] == PRESENCE:  # a held-out distractor never copies another object's look
        concept = pairs[0][1]
        seen |= {
            o.value(concept)
            for o in task.scene.objects
            if o.present and (o.slot, concept) not in pairs and concept in dict(o.values)
        }
    seen |= {sc.obj(s).value(c) for sc in train for s, c in pairs if sc.obj(s).present}
    slot, concept = pairs[0]
    accepted = world.space.accepted(task.reward, slot, concept)
    unseen = [v for v in accepted if v not in seen]
    if len(unseen) < MIN_VALUES:
        return Holdout(used, n_held)
    picked = set(rng.permutation(unseen)[: len(unseen) // 2].tolist())
    values = tuple(v for v in unseen if v in picked)
    return Holdout(used, n_held, tuple((s, c, values) for s, c in pairs))
