"""Filling a finetuning budget: the demonstration plus variants over one user concept.

A *variant* of a demonstration keeps its actions and edits every one of its states the same
way (policy/augment.py's rule): a TI look takes another acceptable instantiation; a TI presence
removes the object or adds it in an acceptable look at a place off the demonstrated path
(`world.placements`). A user concept covering several slots (DoorKey's three lava tiles) picks
an option for each slot independently, so its variants are drawn from the product of the
slots' options. That product can be huge (two tabletop distractors: ~5 * 10^7), so variants
are drawn from a seeded random order of it instead of being enumerated, skipping any that
leave the scene unchanged, repeat an earlier variant's scene or stack two objects on one place.

Variants are made from *sources*: the user's demonstration of the test task and the base
policy's own training demonstrations, each edited as R' allows (a label says a concept does
not matter anywhere, not only in the scene it was given in). Sources are taken in turn, those
with a layout unlike the test task's first, so a small budget spreads over many layouts.

The stream of variants for one (source, concept) is fixed by the seed, and a budget takes a
prefix of the walk over the sources: a larger budget keeps every trajectory of a smaller one.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from dfa_viz.experiment.conditions import UserConcept, in_scene, stable_int
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
    seen: set[Scene] | None = None,
) -> Iterator[tuple[Op, ...]]:
    """Distinct variants (tuples of ops) of the task's scene over `concept`, in a seeded order.

    Variants equal to the task's own scene, equal to a scene in `seen` (an earlier variant's,
    of this stream or of any stream sharing the set), or stacking two objects on one place
    are skipped; each variant yielded is added to `seen`. Ends when the options run out.
    """
    options = member_options(world, task, demo, concept, informed=informed)
    sizes = [len(o) for o in options]
    total = math.prod(sizes)
    if total == 0:
        return
    seen = set() if seen is None else seen
    seen.add(task.scene)

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


def concept_rng(world: str, shift: str, seed: int, concept: str, informed: bool, source: int = 0):
    return np.random.default_rng(
        [seed, stable_int("variants", world, shift, concept, int(informed)), source]
    )


@dataclass(frozen=True)
class Source:
    """A demonstration variants are made from, and the task that says which edits fit it:
    the test task's R' over this demonstration's own initial scene."""

    task: Task
    demo: Trajectory


def same_layout(a: Scene, b: Scene) -> bool:
    """True when every object present in `a` and the agent stand where they do in `b`."""
    return a.agent[:2] == b.agent[:2] and all(
        o.pos == b.obj(o.slot).pos for o in a.objects if o.present
    )


def sources(task: Task, demo: Trajectory, known: Sequence[Trajectory]) -> list[Source]:
    """The demonstrations variants are taken from, in turn: one known demonstration (the base
    policy's training demonstrations) per layout unlike the test task's, then the user's
    demonstration, then the rest. Small budgets thereby cover as many layouts as they can."""
    first: list[Trajectory] = []
    rest: list[Trajectory] = []
    for d in known:
        covered = [task.scene, *(f.scenes[0] for f in first)]
        unlike = not any(same_layout(d.scenes[0], c) for c in covered)
        (first if unlike else rest).append(d)
    return [
        *(Source(task.with_scene(d.scenes[0]), d) for d in first),
        Source(task, demo),
        *(Source(task.with_scene(d.scenes[0]), d) for d in rest),
    ]


def variants_from_sources(
    world: World,
    srcs: Sequence[Source],
    pick: Callable[[int], UserConcept],
    n: int,
    *,
    informed: bool,
    seed: int,
    n_concepts: int = 1,
) -> list[tuple[int, tuple[Op, ...]]]:
    """n variants as (source index, ops): the i-th over the concept pick(i), from the next
    source in turn that still has a new variant of it (each (source, concept) has its own
    seeded stream). Fewer when the concepts run out: a concept found in no source is dropped,
    and the walk ends once all `n_concepts` concepts have been dropped."""
    streams: dict[tuple[int, str], Iterator[tuple[Op, ...]]] = {}
    # two sources can share a layout (the user's scene may be a training scene with one
    # concept changed), so all streams share one seen-set: a variant is new only if no
    # source and no earlier variant of any stream has its scene
    seen = {src.task.scene for src in srcs}

    def stream(k: int, concept: UserConcept) -> Iterator[tuple[Op, ...]]:
        key = (k, concept.name)
        if key not in streams:
            part = in_scene(concept, srcs[k].task.scene)
            rng = concept_rng(world.name, srcs[k].task.shift, seed, concept.name, informed, k)
            streams[key] = (
                iter(())
                if part is None
                else variant_stream(
                    world, srcs[k].task, srcs[k].demo, part, informed=informed, rng=rng, seen=seen
                )
            )
        return streams[key]

    out: list[tuple[int, tuple[Op, ...]]] = []
    dropped: set[str] = set()
    turn, i = 0, 0
    while len(out) < n and len(dropped) < n_concepts:
        concept = pick(i)
        i += 1
        if concept.name in dropped:
            continue
        for j in range(len(srcs)):
            k = (turn + j) % len(srcs)
            ops = next(stream(k, concept), None)
            if ops is not None:
                out.append((k, ops))
                turn = k + 1
                break
        else:
            dropped.add(concept.name)
    return out


def render_from_sources(
    world: World, srcs: Sequence[Source], variants: Sequence[tuple[int, tuple[Op, ...]]]
) -> list[Trajectory]:
    """The variants' trajectories, in order (one batched render per source)."""
    out: list[Trajectory | None] = [None] * len(variants)
    for k, src in enumerate(srcs):
        mine = [i for i, (kk, _) in enumerate(variants) if kk == k]
        for i, traj in zip(
            mine, render_variants(world, src.demo, [variants[i][1] for i in mine]), strict=True
        ):
            out[i] = traj
    return [t for t in out if t is not None]


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
    srcs: Sequence[Source],
    concept: UserConcept,
    n: int,
    *,
    informed: bool,
    seed: int,
) -> list[tuple[int, tuple[Op, ...]]]:
    """The first n variants over one concept, taken from the sources in turn."""
    return variants_from_sources(world, srcs, lambda i: concept, n, informed=informed, seed=seed)


def random_concept_variants(
    world: World,
    srcs: Sequence[Source],
    concepts: Sequence[UserConcept],
    n: int,
    *,
    seed: int,
) -> list[tuple[int, tuple[Op, ...]]]:
    """NH-random: n variants, the i-th over a concept drawn uniformly from `concepts` (every
    instantiation allowed), taken from the sources in turn."""
    rng = np.random.default_rng([seed, stable_int("nh_random", world.name, srcs[0].task.shift)])
    picks: list[UserConcept] = []

    def pick(i: int) -> UserConcept:
        while len(picks) <= i:
            picks.append(concepts[int(rng.integers(len(concepts)))])
        return picks[i]

    return variants_from_sources(
        world, srcs, pick, n, informed=False, seed=seed, n_concepts=len(concepts)
    )
