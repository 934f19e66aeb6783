"""Filling a finetuning budget: the demonstration plus variants of it over one user concept.

A *variant* of the demonstration keeps its actions and edits every one of its states the same
way (policy/augment.py's rule): a TI look takes another acceptable instantiation; a TI presence
removes the object or adds it in an acceptable look at a place off the demonstrated path
(`world.placements`). A user concept covering several slots (DoorKey's three lava tiles) picks
an option for each slot independently, so its variants are drawn from the product of the
slots' options. That product can be huge (two tabletop distractors: ~5 * 10^7), so variants
are drawn from a seeded random order of it instead of being enumerated, skipping any that
leave the scene unchanged, repeat an earlier variant's scene or stack two objects on one place.

The stream of variants for one (task, concept) is fixed by the seed, and a budget takes a
prefix of it: a larger budget keeps every trajectory of a smaller one.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence

import numpy as np

from dfa_viz.experiment.conditions import UserConcept, stable_int
from policy.augment import transform
from sim.core import ABSENT, PRESENCE, PRESENT, Scene, Task, Trajectory, World

# Below this many combinations a concept's options are walked in one seeded permutation;
# above it, combinations are drawn at random (with a seen-set) until enough are found.
PERMUTE_BELOW = 200_000
MAX_DRAWS = 20_000

Op = tuple  # ("set", slot, concept, value) | ("remove", slot) | ("add", slot, look, pos)


def acceptable(world: World, task: Task, slot: str, concept: str, informed: bool) -> tuple:
    """The instantiations a user accepts for a TI label on (slot, concept).

    informed (a person labelling from R'): the values R' allows when it leaves the concept
    open, else every value (the user wrongly calls a concept R' fixes irrelevant), as the
    simulated user of dfa_viz/users.py does. Uninformed (NH-random): every value.
    """
    if informed:
        allowed = task.reward.allowed_values(slot, concept)
        if allowed and len(allowed) > 1:
            return tuple(allowed)
    if concept == PRESENCE:
        return (PRESENT, ABSENT)
    return world.space.slot(slot).concept(concept).values


def member_options(
    world: World, task: Task, demo: Trajectory, concept: UserConcept, *, informed: bool
) -> list[list[Op]]:
    """For each (slot, concept) the user concept covers, the edits a variant may make to it."""
    per_member: list[list[Op]] = []
    for slot, name in concept.members:
        if name != PRESENCE:
            values = acceptable(world, task, slot, name, informed)
            per_member.append([("set", slot, name, v) for v in values])
            continue
        presence = acceptable(world, task, slot, PRESENCE, informed)
        ops: list[Op] = [("remove", slot)] if ABSENT in presence else []
        if PRESENT in presence:
            s = world.space.slot(slot)
            names = [c.name for c in s.concepts]
            looks = itertools.product(
                *(acceptable(world, task, slot, c.name, informed) for c in s.concepts)
            )
            places = world.placements(task, slot, demo)
            ops += [
                ("add", slot, tuple(zip(names, look, strict=True)), pos)
                for look in looks
                for pos in places
            ]
        per_member.append(ops)
    return per_member


def _stacked(scene: Scene, ops: Sequence[Op]) -> bool:
    """True when an added object shares its place with another present object."""
    added = {op[1] for op in ops if op[0] == "add"}
    if not added:
        return False
    places = [tuple(np.round(o.pos[:2], 6)) for o in scene.objects if o.present]
    return len(places) != len(set(places))


def variant_stream(
    world: World,
    task: Task,
    demo: Trajectory,
    concept: UserConcept,
    *,
    informed: bool,
    rng: np.random.Generator,
) -> Iterator[tuple[Op, ...]]:
    """Distinct variants (tuples of ops) of the task's scene over `concept`, in a seeded order.

    Variants equal to the task's own scene, equal to an earlier variant, or stacking two
    objects on one place are skipped. Ends when the options are exhausted.
    """
    options = member_options(world, task, demo, concept, informed=informed)
    sizes = [len(o) for o in options]
    total = math.prod(sizes)
    if total == 0:
        return
    seen = {task.scene}

    def decode(index: int) -> tuple[Op, ...]:
        ops = []
        for opts, n in zip(options, sizes, strict=True):
            index, i = divmod(index, n)
            ops.append(opts[i])
        return tuple(ops)

    if total <= PERMUTE_BELOW:
        indices: Iterator[int] = (int(i) for i in rng.permutation(total))
    else:
        indices = (int(rng.integers(total)) for _ in range(MAX_DRAWS))
    for index in indices:
        ops = decode(index)
        scene = transform(task.scene, ops)
        if scene in seen or _stacked(scene, ops):
            continue
        seen.add(scene)
        yield ops


def concept_rng(world: str, shift: str, seed: int, concept: str, informed: bool):
    return np.random.default_rng(
        [seed, stable_int("variants", world, shift, concept, int(informed))]
    )


def render_variants(world: World, demo: Trajectory, variants: list[tuple[Op, ...]]):
    """The demonstration re-rendered under each variant, its actions kept (one batched render)."""
    if not variants:
        return []
    scenes = [tuple(transform(s, ops) for s in demo.scenes) for ops in variants]
    frames = world.render_batch([s for traj in scenes for s in traj])  # (V*(T+1), H, W, 3)
    frames = frames.reshape(len(variants), len(demo.scenes), *frames.shape[1:])
    return [
        Trajectory(traj, frames[i], demo.actions, demo.success) for i, traj in enumerate(scenes)
    ]


def fill_budget(demo: Trajectory, variants: list[Trajectory], budget: int) -> list[Trajectory]:
    """Exactly `budget` trajectories: the demonstration and the distinct variants, cycled.

    When there are fewer distinct trajectories than the budget, the list repeats from the
    demonstration on (demo, v1, ..., vk, demo, v1, ...): the budget is always the number of
    trajectories finetuned on, and every distinct one is weighted equally (within one).
    """
    assert budget >= 1, f"a budget is at least the one demonstration, not {budget}"
    distinct = [demo, *variants]
    return [distinct[i % len(distinct)] for i in range(budget)]


def variants_for_concept(
    world: World,
    task: Task,
    demo: Trajectory,
    concept: UserConcept,
    n: int,
    *,
    informed: bool,
    seed: int,
) -> list[tuple[Op, ...]]:
    """The first n variants of the concept's seeded stream (fewer when it has fewer)."""
    rng = concept_rng(world.name, task.shift, seed, concept.name, informed)
    stream = variant_stream(world, task, demo, concept, informed=informed, rng=rng)
    return list(itertools.islice(stream, n))


def random_concept_variants(
    world: World,
    task: Task,
    demo: Trajectory,
    concepts: Sequence[UserConcept],
    n: int,
    *,
    seed: int,
) -> tuple[list[tuple[Op, ...]], list[str]]:
    """NH-random: n variants, each over a concept drawn uniformly from `concepts`.

    The i-th draw picks the concept of the i-th variant; each concept's variants come from its
    own stream (every instantiation allowed). Returns the variants and their concepts' names.
    """
    rng = np.random.default_rng([seed, stable_int("nh_random", world.name, task.shift)])
    picks = [concepts[int(rng.integers(len(concepts)))] for _ in range(n)]
    streams = {
        c.name: variant_stream(
            world,
            task,
            demo,
            c,
            informed=False,
            rng=concept_rng(world.name, task.shift, seed, c.name, False),
        )
        for c in concepts
    }
    variants, names = [], []
    for c in picks:
        ops = next(streams[c.name], None)
        if ops is not None:
            variants.append(ops)
            names.append(c.name)
    return variants, names
