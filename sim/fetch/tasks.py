"""Fetch tasks: where they start (the environment's own resets) and what the table offers; the
shifts, fresh tasks and distractor places are made from these by sim.mjworld.tasks.

Positions come from the environment's own reset (its object and goal sampling), seeded; the
training distribution keeps the resets whose object (the goal, in Reach) lies at most
`train_max_dx_m` beyond the gripper's start along x, and `other` keeps those at least
`unseen_min_dx_m` beyond it, where no training task puts it (sim.fetch.world.FetchTask).
"""

from __future__ import annotations

import numpy as np

from sim.core import Scene
from sim.mjworld import tasks as MT

TABLE_TOP_M = 0.4
TABLE_X_M, TABLE_Y_M = (1.12, 1.48), (0.5, 1.0)  # where a distractor may stand (reachable)
RESETS_TRIED = 200  # env seeds tried for one task before giving up
PATH_STEP_M = 0.05  # a way kept clear is kept clear at points this far apart


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
            if (dx >= world.task.unseen_min_dx_m) if unseen else (dx <= world.task.train_max_dx_m):
                return scene
    raise RuntimeError(f"{world.name}: no reset of seed {seed} puts the object where asked")


def keep_clear(world, scene: Scene) -> list[np.ndarray]:
    """The (x, y) a distractor must keep clear of: the goal, the object, the gripper's start
    (and, where the task says so, the way between the object and the goal)."""
    pts = [world.goal_of(scene)[:2]]
    if "object" in world.built:
        pts.append(np.asarray(scene.obj("object").pos[:2]))
    with world._lock:
        pts.append(np.asarray(world._open().initial_gripper_xpos[:2]))
    if world.task.clear_path:  # and the way from the object to the goal
        a, b = pts[1], pts[0]
        steps = int(np.linalg.norm(b - a) / PATH_STEP_M) + 1
        pts += [a + (b - a) * k / steps for k in range(1, steps)]
    return pts


def way(world, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """From the object to the goal (none in Reach)."""
    if "object" not in world.built:
        return None
    return np.asarray(scene.obj("object").pos[:2]), world.goal_of(scene)[:2]
