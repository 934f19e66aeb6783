"""`dfa/Nav2D-v0`: the 2D navigation world as a gymnasium environment."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from sim.core import Scene, Task
from sim.nav2d import render as R
from sim.nav2d.world import HORIZON, Nav2DWorld


class Nav2DEnv(gym.Env):
    """Observations uint8 (36, 36, 3); actions float32 (2,) in [-1, 1]; 20 steps.

    reset(options={"scene": Scene}) or options={"task": Task} starts from that scene; with no
    options it starts from the training task. Reward: minus the distance to the goal.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = "rgb_array") -> None:
        self.world = Nav2DWorld()
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Box(0, 255, (R.SIZE_PX, R.SIZE_PX, 3), np.uint8)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.task: Task = self.world.train_task()
        self.scene: Scene = self.task.scene
        self.history: list[Scene] = [self.scene]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        self.task = options.get("task") or self.world.train_task()
        self.scene = options.get("scene") or self.task.scene
        self.history = [self.scene]
        return self.world.render(self.scene), {"scene": self.scene}

    def step(self, action):
        action = np.asarray(action, np.float32).reshape(1, 2)
        self.scene = self.world.step_batch([self.scene], action)[0]
        self.history.append(self.scene)
        gx, gy = self.scene.obj("goal").pos
        reward = -float(np.hypot(self.scene.agent[0] - gx, self.scene.agent[1] - gy))
        truncated = self.scene.agent[2] >= HORIZON
        info: dict[str, Any] = {"scene": self.scene}
        if truncated:
            info["success"] = self.world.success(self.task, self.history)
        return self.world.render(self.scene), reward, False, truncated, info

    def render(self):
        return self.world.render(self.scene)
