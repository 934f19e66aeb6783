"""The sweep's rollouts, lockstep and lean: every rollout of a unit stepped together, only the
scenes still going stepped and rendered (an ended scene does not change: its frame is its last
one), whether each has ended worked out once per step, and no frames kept. The policy sees the
very batches `World.rollout_batch` would give it, so the outcomes are the same to the bit; the
expert's actions are replayed without rendering at all, once per group of scenes that differ
only in the world's appearance concepts (the tabletop's colours: drawn, never simulated)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim.core import Obj, Scene, Task, UserError, World

FRAME_BYTES = 256 << 20  # frames one lockstep batch may hold
MAX_BATCH = 1024  # rollouts per lockstep batch


@dataclass(frozen=True)
class Run:
    """What the sweep keeps of one rollout."""

    success: bool
    actions: np.ndarray  # (T, A) float32 | (T,) int64
    live: np.ndarray  # (T,) bool: the episode had not ended before step t


def batch_size(world: World) -> int:
    """Rollouts per lockstep batch: its frames within FRAME_BYTES, at most MAX_BATCH."""
    h, w, c = world.obs_shape
    return int(np.clip(FRAME_BYTES // ((world.horizon + 1) * h * w * c), 1, MAX_BATCH))


def roll(
    world: World,
    act: Callable[[np.ndarray], np.ndarray],
    tasks: Sequence[Task],
    scenes: Sequence[Scene],
) -> list[Run]:
    """The policy `act` rolled out from each scene (judged by its task's R'), batch_size at a
    time, as World.rollout_batch does: every rollout of a batch acts each step until all have
    ended (an ended scene does not change, whatever the action)."""
    out: list[Run] = []
    step = batch_size(world)
    for i in range(0, len(scenes), step):
        out += _roll(world, act, tasks[i : i + step], scenes[i : i + step])
    return out


def _roll(world, act, tasks: Sequence[Task], scenes: Sequence[Scene]) -> list[Run]:
    n, horizon = len(scenes), world.horizon
    cur = list(scenes)
    history = [[s] for s in cur]
    live = np.zeros((n, horizon), bool)
    ended = np.array([world.done(s) for s in cur], bool)  # (B,)
    frames = world.render_batch(cur)  # (B, H, W, 3)
    actions: list[np.ndarray] = []
    for t in range(horizon):
        live[:, t] = ~ended
        if actions and ended.all():
            break
        a = np.asarray(act(frames))  # (B, A) | (B,)
        if not world.discrete and not np.isfinite(a).all():
            raise UserError(
                f"the policy's actions at step {t} are not finite numbers: a policy with "
                "non-finite outputs cannot be rolled out or scored"
            )
        actions.append(a)
        going = np.flatnonzero(~ended)
        moved = world.step_batch([cur[k] for k in going], a[going])
        for k, s in zip(going, moved, strict=True):
            cur[k] = s
        for h, s in zip(history, cur, strict=True):
            h.append(s)
        if t + 1 < horizon and len(going):
            ended[going] = [world.done(s) for s in moved]
            frames = frames.copy()
            frames[going] = world.render_batch(moved)  # an ended scene's frame stays
    for h in history:
        h += [h[-1]] * (horizon + 1 - len(h))
    acts = _padded(actions, horizon, n, world.discrete)  # (B, T[, A])
    return [
        Run(bool(world.success(task, h)), acts[k], live[k])
        for k, (task, h) in enumerate(zip(tasks, history, strict=True))
    ]


def _padded(actions: list[np.ndarray], horizon: int, n: int, discrete: bool) -> np.ndarray:
    """(B, T[, A]): the actions of each step, the last repeated once every episode has ended
    (as World.rollout_batch records them)."""
    if not actions:
        return np.zeros((n, horizon), np.int64) if discrete else np.zeros((n, horizon, 0))
    actions = actions + [actions[-1]] * (horizon - len(actions))
    return np.stack(actions, axis=1)


def replay_success(
    world: World, tasks: Sequence[Task], scenes: Sequence[Scene], actions: np.ndarray
) -> list[bool]:
    """Whether actions (B, T[, A]) played from each scene meet its task's R' (what
    World.rollout_batch with those actions judges, nothing rendered). Scenes that differ only
    in the world's appearance concepts, given the same actions, are stepped once: the others
    take that history with their own looks (World.appearance_concepts)."""
    first: dict[tuple, int] = {}
    stepped = [
        first.setdefault(_moves(world, s, a), i)
        for i, (s, a) in enumerate(zip(scenes, actions, strict=True))
    ]
    reps = sorted(set(stepped))
    cur = [scenes[i] for i in reps]
    history = [[s] for s in cur]
    for t in range(world.horizon):
        a = actions[reps, min(t, actions.shape[1] - 1)]
        cur = world.step_batch(cur, a)
        for h, s in zip(history, cur, strict=True):
            h.append(s)
    of = dict(zip(reps, history, strict=True))
    return [
        bool(world.success(task, [scene, *(_looking(s, scene) for s in of[rep][1:])]))
        for task, scene, rep in zip(tasks, scenes, stepped, strict=True)
    ]


def _moves(world: World, scene: Scene, actions: np.ndarray) -> tuple:
    """What a replay from `scene` depends on: the actions and the scene but for its looks."""
    looks = world.appearance_concepts
    objects = tuple(
        (o.slot, o.present, tuple(v for v in o.values if v[0] not in looks), o.pos)
        for o in scene.objects
    )
    return (actions.tobytes(), scene.world, scene.agent, objects)


def _looking(stepped: Scene, like: Scene) -> Scene:
    """`stepped` with the looks (every object's values) of `like`."""
    objects = tuple(
        o if o.values == w.values else Obj(o.slot, o.present, w.values, o.pos)
        for o, w in zip(stepped.objects, like.objects, strict=True)
    )
    return Scene(stepped.world, objects, stepped.agent)
