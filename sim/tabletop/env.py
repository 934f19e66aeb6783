"""`dfa/Tabletop-v0`: the tabletop pick-and-place world as a gymnasium environment."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from sim.core import Scene, Task
from sim.tabletop.tasks import VIEW_HALF_M
from sim.tabletop.world import TabletopWorld


class TabletopEnv(gym.Env):
    """Observations uint8 (80, 80, 3); actions float32 (4,) = (pick_x, pick_y, place_x,
    place_y) in [-0.4, 0.4] metres; one step per episode.

    reset(options={"scene": Scene}) or options={"task": Task} starts from that scene; with no
    options it starts from the training task. Reward: minus the distance (m) from the object's
    centre to the goal's after the primitive; info["success"] is R' judged on the episode.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 2}

    def __init__(self, render_mode: str | None = "rgb_array", world: TabletopWorld | None = None):
        self.world = world or TabletopWorld()
        self.render_mode = render_mode
        h, w, c = self.world.obs_shape
        self.observation_space = gym.spaces.Box(0, 255, (h, w, c), np.uint8)
        self.action_space = gym.spaces.Box(-VIEW_HALF_M, VIEW_HALF_M, (4,), np.float32)
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
        action = np.asarray(action, np.float32).reshape(1, 4)
        self.scene = self.world.step_batch([self.scene], action)[0]
        self.history.append(self.scene)
        o, g = self.scene.obj("object").pos, self.scene.obj("goal").pos
        reward = -float(np.hypot(o[0] - g[0], o[1] - g[1]))
        terminated = self.world.done(self.scene)
        info: dict[str, Any] = {"scene": self.scene}
        if terminated:
            info["success"] = self.world.success(self.task, self.history)
        return self.world.render(self.scene), reward, terminated, False, info

    def render(self):
        return self.world.render(self.scene)
