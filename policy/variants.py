"""Augmentation: variants of demonstrations over the concepts the user called task-irrelevant.

A *variant* of a demonstration keeps its actions and edits every one of its states the same
way (sim.core.ops): a TI look takes another acceptable instantiation; a TI presence removes the
object or adds it, in an acceptable look, at a place off the demonstrated path
(`world.placements`). What the user called irrelevant is an `Irrelevant`: one user concept (a
kind's concept: "lava.presence" covers every lava tile, as a person means it) or several, with
the instantiations that are fine for each (slot, concept) it covers. A variant picks one option
for each of them, so variants come from the product of their options. That product can be huge
(two tabletop distractors: ~5 * 10^7), so variants are drawn from a seeded random order of it
instead of being listed, skipping any that leave the scene unchanged, repeat an earlier
variant's scene or stack two objects on one place.

Variants are made from *sources*: the user's demonstration of the test task and the base
policy's own training demonstrations, each edited as R' allows (a label says a concept does not
matter anywhere, not only in the scene it was given in). Sources are taken in turn, those with
a layout unlike the test task's first, so a small budget spreads over many layouts. The stream
of variants of one (source, concept) is fixed by the seed, and n variants are a prefix of the
walk over the sources: more variants keep every one of fewer.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from itertools import product

import numpy as np

from sim.core import (
    ABSENT,
    PRESENCE,
    PRESENT,
    Feedback,
    Scene,
    Task,
    Trajectory,
    UserConcept,
    World,
)
from sim.core.ops import Add, Op, Remove, SetValue, stacked, transform

# Below this many combinations an Irrelevant's options are walked in one seeded permutation;
# above it, combinations are drawn at random (with a seen-set) until enough are found.
PERMUTE_BELOW = 200_000
MAX_DRAWS = 20_000

Variant = tuple[Op, ...]


def stable_int(*parts: object) -> int:
    """A process-independent integer from names (Python's hash() is salted per process)."""
    return zlib.crc32("/".join(map(str, parts)).encode())


@dataclass(frozen=True)
class Irrelevant:
    """What a variant may change: the (slot, concept) pairs called task-irrelevant, each with
    the instantiations that are fine for it.

    name: the user concepts it stands for ("goal.colour", "lava.presence", joined by "+").
    informed: the looks of an added object follow R' (a person who knows what they want);
        otherwise any look (NH-random's uninformed augmentation).
    held: (slot, concept, values) no variant may show, set or added (values the evaluation
        keeps for itself: policy.heldout).
    """

    name: str
    members: tuple[tuple[str, str, tuple[str, ...]], ...]
    informed: bool = True
    held: tuple[tuple[str, str, tuple[str, ...]], ...] = ()

    def in_scene(self, scene: Scene) -> Irrelevant | None:
        """The part a scene shows: presence, and the looks of objects present in it."""
        members = tuple(m for m in self.members if m[1] == PRESENCE or scene.obj(m[0]).present)
        return Irrelevant(self.name, members, self.informed, self.held) if members else None

    def allows(self, slot: str, concept: str, value: str) -> bool:
        """False when `value` of slot.concept is held out."""
        return not any((s, c) == (slot, concept) and value in v for s, c, v in self.held)


def from_feedback(world: World, feedback: Feedback) -> Irrelevant | None:
    """The TI labels of `feedback` as what variants may change; a label speaks for its slot's
    kind (lava0.presence TI: no lava tile matters). None when no label is TI."""
    labels = feedback.irrelevant
    if not labels:
        return None
    space = world.space
    by_pair = {(lab.slot, lab.concept): lab for lab in labels}
    names: list[str] = []
    members: list[tuple[str, str, tuple[str, ...]]] = []
    for lab in labels:
        uc = space.user_concept(lab.slot, lab.concept)
        if uc.name in names:
            continue
        names.append(uc.name)
        for slot, concept in uc.members:
            said = by_pair.get((slot, concept), lab)
            members.append((slot, concept, said.acceptable or space.values(slot, concept)))
    return Irrelevant("+".join(sorted(names)), tuple(members))


# -- sources ------------------------------------------------------------------------------------
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


def sources(task: Task, demo: Trajectory, known: Sequence[Trajectory] = ()) -> list[Source]:
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


def acceptable_if_irrelevant(world: World, reward, slot: str, concept: str) -> tuple[str, ...]:
    """What a person who calls slot.concept task-irrelevant accepts, knowing what they want
    (R'): the values R' accepts when it leaves the concept open; every value when R' fixes
    it (they are wrong about the concept, and say that any value will do)."""
    accepted = world.space.accepted(reward, slot, concept)
    return accepted if len(accepted) > 1 else world.space.values(slot, concept)


def over(world: World, task: Task, uc: UserConcept, *, informed: bool = True) -> Irrelevant:
    """A user concept called task-irrelevant, with what a person accepts for each (slot,
    concept) it covers (acceptable_if_irrelevant), or any value when uninformed."""
    members = tuple(
        (
            s,
            c,
            acceptable_if_irrelevant(world, task.reward, s, c)
            if informed
            else world.space.values(s, c),
        )
        for s, c in uc.members
    )
    return Irrelevant(uc.name, members, informed)


# -- variant streams ----------------------------------------------------------------------------
def looks_of(world: World, task: Task, slot: str, *, informed: bool) -> list[tuple]:
    """Every look an added `slot` may take: for each of its concepts what a person accepts
    (acceptable_if_irrelevant), or any instantiation when uninformed."""
    concepts = world.space.slot(slot).concepts
    per_concept = [
        acceptable_if_irrelevant(world, task.reward, slot, c.name) if informed else c.values
        for c in concepts
    ]
    names = [c.name for c in concepts]
    return [tuple(zip(names, look, strict=True)) for look in product(*per_concept)]


def options(world: World, src: Source, what: Irrelevant) -> list[list[Op]]:
    """For each (slot, concept) of `what`, the ops a variant of `src` may make to it."""
    out: list[list[Op]] = []
    for slot, concept, values in what.members:
        if concept != PRESENCE:
            out.append(
                [SetValue(slot, concept, v) for v in values if what.allows(slot, concept, v)]
            )
            continue
        ops: list[Op] = [Remove(slot)] if ABSENT in values else []
        if PRESENT in values:
            places = world.placements(src.task, slot, src.demo)
            looks = [
                look
                for look in looks_of(world, src.task, slot, informed=what.informed)
                if all(what.allows(slot, c, v) for c, v in look)
            ]
            ops += [Add(slot, look, pos) for look in looks for pos in places]
        out.append(ops)
    return out


def _like(op: Op, scene: Scene) -> bool:
    """True when `op` gives its object what it has in `scene` (the test task's): the same
    value, the same presence, the same look."""
    o = scene.obj(op.slot)
    if isinstance(op, SetValue):
        return o.value(op.concept) == op.value
    if isinstance(op, Remove):
        return not o.present
    return o.present and op.values == o.values


def _order(opts: list[list[Op]], like: Scene, rng: np.random.Generator) -> Iterator[int]:
    """Indices into the product of `opts` (decoded as in variant_stream), in a seeded random
    order with the combinations most like `like` first: those whose every op gives its object
    what it has there, then those with one op unlike it, and so on. Above PERMUTE_BELOW
    combinations, the combinations of like ops come first and random draws follow."""
    sizes = [len(o) for o in opts]
    total = math.prod(sizes)
    unlike = [np.array([not _like(op, like) for op in choices]) for choices in opts]
    if total <= PERMUTE_BELOW:
        perm = rng.permutation(total)  # (total,)
        distance = np.zeros(total, np.int64)
        rest = perm.copy()
        for n, u in zip(sizes, unlike, strict=True):  # digit k of every index, as decode reads it
            rest, digit = np.divmod(rest, n)
            distance += u[digit]
        yield from (int(i) for i in perm[np.argsort(distance, kind="stable")])
        return
    near = [np.flatnonzero(~u) if (~u).any() else np.arange(len(u)) for u in unlike]
    if math.prod(len(c) for c in near) <= PERMUTE_BELOW:
        radix = np.cumprod([1, *sizes[:-1]])
        for flat in rng.permutation(math.prod(len(c) for c in near)):
            index, rest = 0, int(flat)
            for choices, r in zip(near, radix, strict=True):
                rest, j = divmod(rest, len(choices))
                index += int(choices[j]) * int(r)
            yield index
    yield from (int(rng.integers(total)) for _ in range(MAX_DRAWS))


def variant_stream(
    world: World,
    src: Source,
    what: Irrelevant,
    *,
    rng: np.random.Generator,
    seen: set[Scene],
    like: Scene,
) -> Iterator[Variant]:
    """Distinct variants of the source's scene over `what`, in a seeded order, those closest
    to `like` (the test task's scene) first: a source takes the looks the test task has before
    any other, so that a small budget holds what the user saw go wrong.

    Variants equal to a scene in `seen` (the sources' own, an earlier variant's of any stream
    sharing the set) or stacking two objects on one place are skipped; each variant yielded
    is added to `seen`. Ends when the options run out.
    """
    opts = options(world, src, what)
    sizes = [len(o) for o in opts]
    if math.prod(sizes) == 0:
        return

    def decode(index: int) -> Variant:
        ops = []
        for choices, n in zip(opts, sizes, strict=True):
            index, i = divmod(index, n)
            ops.append(choices[i])
        return tuple(ops)

    for index in _order(opts, like, rng):
        ops = decode(index)
        scene = transform(src.task.scene, ops)
        if scene in seen or stacked(scene, ops):
            continue
        seen.add(scene)
        yield ops


def spread_looks(scene: Scene, what: Irrelevant) -> list[Scene]:
    """`variants`' like that spreads a budget over the looks `what` allows: the j-th scene gives
    each look concept (not presence) its j-th allowed value counted on from `scene`'s own."""
    looks = []
    for slot, concept, values in what.members:
        allowed = [v for v in values if concept != PRESENCE and what.allows(slot, concept, v)]
        if allowed:
            first = allowed.index(now) if (now := scene.obj(slot).value(concept)) in allowed else 0
            looks.append((slot, concept, allowed[first:] + allowed[:first]))
    out = []
    for j in range(max((len(v) for _, _, v in looks), default=1)):
        for slot, concept, allowed in looks:
            scene = scene.with_obj(scene.obj(slot).with_value(concept, allowed[j % len(allowed)]))
        out.append(scene)
    return out


def variants(
    world: World,
    srcs: Sequence[Source],
    pick: Callable[[int], Irrelevant],
    n: int,
    *,
    seed: int,
    like: Scene | Sequence[Scene],
    n_concepts: int = 1,
) -> list[tuple[int, Variant]]:
    """n variants as (source index, ops): the i-th over pick(i), from the next source in turn
    that still has a new variant of it (each (source, concept) has its own seeded stream,
    closest to `like`, the test task's scene, first; or source k's to the k-th of several).
    Fewer when the concepts run out: a concept found in no source is dropped, and the walk
    ends once all `n_concepts` concepts have been dropped."""
    streams: dict[tuple[int, str], Iterator[Variant]] = {}
    # two sources can share a layout (the user's scene may be a training scene with one
    # concept changed), so all streams share one seen-set: a variant is new only if no
    # source and no earlier variant of any stream has its scene
    seen = {src.task.scene for src in srcs}
    likes = [like] if isinstance(like, Scene) else list(like)

    def stream(k: int, what: Irrelevant) -> Iterator[Variant]:
        key = (k, what.name)
        if key not in streams:
            src = srcs[k]
            part = what.in_scene(src.task.scene)
            tag = stable_int("variants", world.name, src.task.shift, what.name, int(what.informed))
            rng = np.random.default_rng([seed, tag, k])
            streams[key] = (
                iter(())
                if part is None
                else variant_stream(
                    world, src, part, rng=rng, seen=seen, like=likes[k % len(likes)]
                )
            )
        return streams[key]

    out: list[tuple[int, Variant]] = []
    dropped: set[str] = set()
    turn, i = 0, 0
    while len(out) < n and len(dropped) < n_concepts:
        what = pick(i)
        i += 1
        if what.name in dropped:
            continue
        for j in range(len(srcs)):
            k = (turn + j) % len(srcs)
            ops = next(stream(k, what), None)
            if ops is not None:
                out.append((k, ops))
                turn = k + 1
                break
        else:
            dropped.add(what.name)
    return out


def render(
    world: World, srcs: Sequence[Source], chosen: Sequence[tuple[int, Variant]]
) -> list[Trajectory]:
    """The variants' trajectories, in order: each source demonstration re-rendered under its
    variants' ops, its actions kept (one batched render per source)."""
    out: list[Trajectory | None] = [None] * len(chosen)
    for k, src in enumerate(srcs):
        mine = [i for i, (kk, _) in enumerate(chosen) if kk == k]
        if not mine:
            continue
        scenes = [tuple(transform(s, chosen[i][1]) for s in src.demo.scenes) for i in mine]
        frames = world.render_batch([s for traj in scenes for s in traj])  # (V*(T+1), H, W, 3)
        frames = frames.reshape(len(mine), len(src.demo.scenes), *frames.shape[1:])
        for j, i in enumerate(mine):
            out[i] = Trajectory(scenes[j], frames[j], src.demo.actions, src.demo.success)
    return [t for t in out if t is not None]


def fill_budget(demo: Trajectory, augmented: Sequence[Trajectory], budget: int) -> list[Trajectory]:
    """Exactly `budget` trajectories: the demonstration and the distinct variants, cycled.

    When there are fewer distinct trajectories than the budget, the list repeats from the
    demonstration on (demo, v1, ..., vk, demo, v1, ...): the budget is always the number of
    trajectories finetuned on, and every distinct one is weighted equally (within one).
    """
    assert budget >= 1, f"a budget is at least the one demonstration, not {budget}"
    distinct = [demo, *augmented]
    return [distinct[i % len(distinct)] for i in range(budget)]


def augment(
    world: World,
    task: Task,
    demo: Trajectory,
    feedback: Feedback,
    *,
    n: int,
    known: Sequence[Trajectory] = (),
    seed: int = 0,
) -> list[Trajectory]:
    """Up to n variants over the TI labels of `feedback`, from the user's demonstration and
    the `known` ones (the base policy's training demonstrations) in turn; [] without a TI
    label."""
    what = from_feedback(world, feedback)
    if what is None or n < 1:
        return []
    srcs = sources(task, demo, known)
    chosen = variants(world, srcs, lambda i: what, n, seed=seed, like=task.scene)
    return render(world, srcs, chosen)
