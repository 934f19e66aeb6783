"""Checking a demonstration someone brought (a file, the page) before anything relies on it.

Nothing in a demonstration but its actions is trusted: the actions are checked (kind, shape,
finite values, one per step of the horizon), its frames and scenes must be the world's and
start from the task's scene, and then the actions are replayed from the task's scene through
the world's own dynamics, which gives the scenes, frames and success that are used.
"""

from __future__ import annotations

import numpy as np

from sim.core.errors import UserError
from sim.core.task import Task
from sim.core.trajectory import Trajectory
from sim.core.world import World


def check_demonstration(
    world: World, task: Task, demo: Trajectory, *, source: str = "the demonstration"
) -> Trajectory:
    """`demo`'s actions replayed from the task's scene, once the file has passed every check;
    a UserError naming `source` and what is accepted otherwise."""
    a = check_actions(world, demo.actions, source=source)
    frames = demo.observations.shape[1:]
    if frames != world.obs_shape:
        raise UserError(
            f"{source}: frames of shape {frames}, but {world.name} renders {world.obs_shape}"
        )
    other = sorted({s.world for s in demo.scenes} - {world.name})
    if other:
        raise UserError(f"{source}: its scenes belong to {', '.join(other)}, not {world.name}")
    if demo.scenes[0] != task.scene:
        raise UserError(f"{source}: the demonstration starts from another scene than the task")
    return world.replay(task, a)


def check_actions(world: World, a: np.ndarray, *, source: str) -> np.ndarray:
    """The actions of a demonstration from outside, as the world takes them (int64 (T,) or
    float32 (T, A), one per step of the horizon, finite); a UserError naming `source` and what
    is accepted otherwise."""
    if world.discrete:
        want = f"integer actions in 0..{world.action_dim - 1} of shape ({world.horizon},)"
        ok = (
            np.issubdtype(a.dtype, np.integer)
            and a.shape == (world.horizon,)
            and bool(((a >= 0) & (a < world.action_dim)).all())
        )
    else:
        want = f"float actions of shape ({world.horizon}, {world.action_dim})"
        ok = np.issubdtype(a.dtype, np.floating) and a.shape == (world.horizon, world.action_dim)
        if ok and not np.isfinite(a).all():
            t = int(np.argwhere(~np.isfinite(a))[0][0])
            raise UserError(f"{source}: the action at step {t} is not a finite number ({a[t]})")
    if not ok:
        raise UserError(
            f"{source}: actions of dtype {a.dtype}, shape {a.shape}; {world.name} needs {want}"
        )
    return a.astype(np.int64 if world.discrete else np.float32)


def require_success(task: Task, demo: Trajectory, *, source: str = "the demonstration") -> None:
    """A demonstration that does not do what R' asks cannot explain a failure: refuse it."""
    if not demo.success:
        raise UserError(
            f'{source} does not succeed at what the task asks ("{task.reward.instruction}"): '
            "the search needs a demonstration of what you want; give another"
        )
