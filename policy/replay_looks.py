"""What the augmentation may change, and the replayed training data re-rendered under it.

Finetuning replays the base policy's own training data (`policy.train.replayed`) so that
fitting the new trajectories does not erase what it did elsewhere. That data shows only the
training looks. The paper treats the policy as a black box and augments only the user's
demonstration, but notes that one could run the same augmentation over the original training
demonstrations too. `varied` does that: every replayed trajectory on a layout finetuning may
start from is re-rendered once under a variant over the TI labels, its actions kept (the
physics does not change with a look). The policy then sees its whole training distribution in
the looks the user accepts, not only the budget's trajectories. Replayed trajectories on
layouts the evaluation holds out (policy.heldout) stay as they are, and no variant shows a
held-out value.

`painted` goes beyond the named values where the world's renderer draws any colour
(World.paints, the MuJoCo worlds): each slot a variant recoloured or added is drawn in a colour
of its own, uniform over red, green and blue, kept PAINT_GAP from every named colour the
variant may not show (held out, or not accepted). A policy then sees a continuum of looks, so
that a held-out colour lies among colours it has seen rather than beside a few.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from policy.heldout import Holdout, plan
from policy.model import Policy
from policy.train import replayed
from policy.variants import (
    Irrelevant,
    Source,
    from_feedback,
    spread_looks,
    stable_int,
    variants,
)
from sim.core import RGB, Feedback, Scene, Task, Trajectory, World
from sim.core.ops import transform

PAINT_GAP = 0.3
"""How far (Euclidean, red, green and blue in [0, 1]) a painted colour stays from every named
colour a variant may not show: held out by the evaluation, or not accepted by R'. About the
MuJoCo palette's closest pair (yellow and orange, 0.36): no painted colour is nearer a held-out
one than two named colours are to each other."""


def irrelevant(
    world: World, task: Task, feedback: Feedback, *, seed: int, held_out: bool = True
) -> tuple[Irrelevant | None, Holdout | None]:
    """What variants may change for `feedback`'s TI labels (None without one), restricted to
    values the evaluation does not hold out, and the evaluation's plan (None where the world
    has no training distribution or held_out is False)."""
    what = from_feedback(world, feedback)
    if what is None or not (held_out and world.benchmark):
        return what, None
    holdout = plan(world, task, seed)
    return holdout.restrict(what), holdout


def varied_scenes(
    world: World,
    task: Task,
    feedback: Feedback,
    replay: Sequence[Trajectory],
    *,
    seed: int,
) -> dict[int, tuple[Scene, ...]]:
    """The scenes a variant over the TI labels gives each replayed trajectory on a layout
    finetuning may start from (one variant each, the accepted looks spread over them), by its
    index in `replay`; none without a TI label. A trajectory no variant falls to is absent."""
    what, holdout = irrelevant(world, task, feedback, seed=seed)
    if what is None:
        return {}
    kept = [i for i, d in enumerate(replay) if holdout is None or holdout.keeps(world, d.scenes[0])]
    srcs = [Source(task.with_scene(replay[i].scenes[0]), replay[i]) for i in kept]
    like = spread_looks(task.scene, what)
    out: dict[int, tuple[Scene, ...]] = {}
    for k, ops in variants(world, srcs, lambda i: what, len(srcs), seed=seed, like=like):
        if kept[k] not in out:
            out[kept[k]] = tuple(transform(s, ops) for s in replay[kept[k]].scenes)
    return dict(sorted(out.items()))


def varied(
    world: World,
    task: Task,
    feedback: Feedback,
    replay: Sequence[Trajectory],
    *,
    seed: int,
) -> list[Trajectory]:
    """`replay` with each trajectory `varied_scenes` varies re-rendered in its new scenes,
    its actions kept; the rest as given."""
    out = list(replay)
    for i, scenes in varied_scenes(world, task, feedback, replay, seed=seed).items():
        d = replay[i]
        frames = world.render_batch(list(scenes))  # (T+1, H, W, 3)
        out[i] = Trajectory(scenes, frames, d.actions, d.success)
    return out


def painted(
    world: World,
    task: Task,
    feedback: Feedback,
    replay: Sequence[Trajectory],
    *,
    seed: int,
) -> list[Trajectory]:
    """`varied`, with every slot a variant recoloured or added drawn in a colour of its own
    from the continuum the world's renderer draws (World.paints), at least PAINT_GAP from
    each named colour the variant may not show; the scenes keep the variant's named look."""
    scenes = varied_scenes(world, task, feedback, replay, seed=seed)
    paints = paint_colours(world, task, feedback, replay, scenes, seed=seed)
    out = list(replay)
    for i, now in scenes.items():
        d = replay[i]
        frames = (  # (T+1, H, W, 3)
            world.render_painted(now, [paints[i]] * len(now))
            if i in paints
            else world.render_batch(list(now))
        )
        out[i] = Trajectory(now, frames, d.actions, d.success)
    return out


def paint_colours(
    world: World,
    task: Task,
    feedback: Feedback,
    replay: Sequence[Trajectory],
    scenes: Mapping[int, Sequence[Scene]],
    *,
    seed: int,
) -> dict[int, dict[str, RGB]]:
    """For each replayed trajectory `varied_scenes` varies (`scenes[i]`), the colour each
    slot it recoloured or added is painted in (seeded)."""
    if world.paints is None:
        raise ValueError(f"{world.name} draws only its named colours")
    what, _ = irrelevant(world, task, feedback, seed=seed)
    if what is None:
        return {}
    concept, named = world.paints.concept, world.paints.rgb
    rng = np.random.default_rng([seed, stable_int("painted", world.name, task.shift, task.seed)])
    out: dict[int, dict[str, RGB]] = {}
    for i in sorted(scenes):
        was, now = replay[i].scenes[0], scenes[i][0]
        slots = [
            o.slot
            for o in now.objects
            if o.present
            and concept in dict(o.values)
            and (not was.obj(o.slot).present or was.obj(o.slot).value(concept) != o.value(concept))
        ]
        colours = {}
        for slot in slots:
            ok = _allowed(world, task, what, slot, concept)
            colours[slot] = _far_from(rng, [rgb for v, rgb in named.items() if v not in ok])
        if colours:
            out[i] = colours
    return out


def _allowed(world: World, task: Task, what: Irrelevant, slot: str, concept: str) -> set[str]:
    """The named values of slot.concept a variant may show."""
    said = next((v for s, c, v in what.members if (s, c) == (slot, concept)), None)
    values = world.space.accepted(task.reward, slot, concept) if said is None else said
    return {v for v in values if what.allows(slot, concept, v)}


def _far_from(rng: np.random.Generator, avoid: Sequence[RGB]) -> RGB:
    """A uniformly drawn colour at least PAINT_GAP from each of `avoid`."""
    far = np.asarray(avoid, float).reshape(-1, 3)  # (K, 3)
    for _ in range(10_000):
        rgb = rng.uniform(0.0, 1.0, 3)
        if not len(far) or np.linalg.norm(far - rgb, axis=1).min() >= PAINT_GAP:
            return (float(rgb[0]), float(rgb[1]), float(rgb[2]))
    raise ValueError(f"no colour is {PAINT_GAP} from each of {len(far)} named colours")


def replay_for(
    world: World,
    base: Policy,
    task: Task,
    feedback: Feedback,
    known: Sequence[Trajectory],
    *,
    looks: str,
    share: float,
    seed: int,
) -> list[Trajectory]:
    """What finetuning `base` replays: its training data (`replayed`; none at share 0), in
    the training looks ("training"), re-rendered over the TI labels ("varied") or, beyond
    the named colours, painted ("painted")."""
    if share == 0:
        return []
    data = replayed(world, base, known)
    remake = {"training": None, "varied": varied, "painted": painted}[looks]
    return data if remake is None else remake(world, task, feedback, data, seed=seed)
