"""Fetch tasks: where they start (the environment's own resets) and what the table offers; the
shifts, fresh tasks and distractor places are made from these by sim.mjworld.tasks.

Positions come from the environment's own reset (its object and goal sampling), seeded; the
training distribution keeps the resets whose object (the goal, in Reach) lies at most
TRAIN_MAX_DX_M beyond the gripper's start along x, and `other` keeps those at least
UNSEEN_MIN_DX_M beyond it, where no training task puts it.
"""

from __future__ import annotations

import numpy as np

from sim.core import Scene
from sim.mjworld import tasks as MT

TRAIN_MAX_DX_M = 0.05
UNSEEN_MIN_DX_M = 0.10
TABLE_TOP_M = 0.4
TABLE_X_M, TABLE_Y_M = (1.12, 1.48), (0.5, 1.0)  # where a distractor may stand (reachable)
RESETS_TRIED = 200  # env seeds tried for one task before giving up


def workspace(has_object: bool) -> MT.Workspace:
    return MT.Workspace(
        TABLE_X_M,
        TABLE_Y_M,
        TABLE_TOP_M,
        recoloured=("object", "table") if has_object else ("table",),
        target=("target", "the target", "target"),
    )


def _dx(world, env, scene: Scene) -> float:
    """How far beyond the gripper's start, along x, the object (the goal in Reach) starts."""
    where = scene.obj("object").pos if "object" in world.built else world.goal_of(scene)
    return float(where[0] - env.initial_gripper_xpos[0])


def reset_scene(world, seed: int, *, unseen: bool = False) -> Scene:
    """A scene from the environment's own reset: the first of its seeds [seed, k] whose object
    lies in the training region (or, `unseen`, beyond it); default looks, no distractor."""
    with world._lock:
        env = world._open()
        for k in range(RESETS_TRIED):
            env.reset(seed=int(np.random.SeedSequence([seed, k]).generate_state(1)[0]))
            goal = tuple(world.env_state(env))
            scene = MT.initial_scene(world, env, {"target": goal, "table": goal})
            dx = _dx(world, env, scene)
            if (dx >= UNSEEN_MIN_DX_M) if unseen else (dx <= TRAIN_MAX_DX_M):
                return scene
    raise RuntimeError(f"{world.name}: no reset of seed {seed} puts the object where asked")


def keep_clear(world, scene: Scene) -> list[np.ndarray]:
    """The (x, y) a distractor must keep clear of: the goal, the object, the gripper's start."""
    pts = [world.goal_of(scene)[:2]]
    if "object" in world.built:
        pts.append(np.asarray(scene.obj("object").pos[:2]))
    with world._lock:
        pts.append(np.asarray(world._open().initial_gripper_xpos[:2]))
    return pts


def way(world, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """From the object to the goal (none in Reach)."""
    if "object" not in world.built:
        return None
    return np.asarray(scene.obj("object").pos[:2]), world.goal_of(scene)[:2]
