"""nav2d's dynamics and success: the agent moves by its clipped action; R' asks it to end on
the goal and, for an avoided distractor, never to come near it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim.core import Scene, Task
from sim.nav2d import render as R

HORIZON = 20
SUCCESS_RADIUS = 1.0  # success: within this distance of the goal after the last step
AVOID_RADIUS = 2.0  # an avoided distractor must never be this close


def dist(a: Sequence[float], b: Sequence[float]) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))


def step_batch(scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
    """Each agent moves by its action clipped to [-1, 1]^2 and the arena; t counts steps."""
    actions = np.asarray(actions, np.float64)
    assert actions.shape == (len(scenes), 2), f"actions must be (B, 2), got {actions.shape}"
    agent = np.array([s.agent for s in scenes], np.float64)  # (B, 3): x, y, t
    live = agent[:, 2] < HORIZON
    xy = np.clip(agent[:, :2] + np.clip(actions, -1.0, 1.0), -R.ARENA, R.ARENA)
    agent[live, :2] = xy[live]
    agent[live, 2] += 1
    return [
        Scene(s.world, s.objects, tuple(float(v) for v in a))
        for s, a in zip(scenes, agent, strict=True)
    ]


def done(scene: Scene) -> bool:
    return scene.agent[2] >= HORIZON


def meets_reward(task: Task, scenes: Sequence[Scene]) -> bool:
    final = scenes[-1]
    if dist(final.agent, final.obj("goal").pos) >= SUCCESS_RADIUS:
        return False
    for slot in task.reward.avoid:
        o = scenes[0].obj(slot)
        if o.present and min(dist(s.agent, o.pos) for s in scenes) < AVOID_RADIUS:
            return False
    return True
