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
"""

from __future__ import annotations

from collections.abc import Sequence

from policy.heldout import Holdout, plan
from policy.model import Policy
from policy.train import replayed
from policy.variants import Irrelevant, Source, from_feedback, render, spread_looks, variants
from sim.core import Feedback, Task, Trajectory, World


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


def varied(
    world: World,
    task: Task,
    feedback: Feedback,
    replay: Sequence[Trajectory],
    *,
    seed: int,
) -> list[Trajectory]:
    """`replay` with each trajectory on a layout finetuning may start from re-rendered once
    under a variant over the TI labels, the accepted looks spread over them; the rest, and all
    of it without a TI label, as given."""
    what, holdout = irrelevant(world, task, feedback, seed=seed)
    if what is None:
        return list(replay)
    kept = [i for i, d in enumerate(replay) if holdout is None or holdout.keeps(world, d.scenes[0])]
    srcs = [Source(task.with_scene(replay[i].scenes[0]), replay[i]) for i in kept]
    like = spread_looks(task.scene, what)
    chosen = variants(world, srcs, lambda i: what, len(srcs), seed=seed, like=like)
    out = list(replay)
    done: set[int] = set()
    for (k, _), traj in zip(chosen, render(world, srcs, chosen), strict=True):
        if k not in done:  # one variant each; a source without one keeps its training look
            out[kept[k]] = traj
            done.add(k)
    return out


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
    the training looks ("training") or re-rendered over the TI labels ("varied")."""
    if share == 0:
        return []
    data = replayed(world, base, known)
    return varied(world, task, feedback, data, seed=seed) if looks == "varied" else data
