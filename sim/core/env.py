"""A World as a gymnasium environment: reset to any scene or task, step, render."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from sim.core.scene import Scene
from sim.core.task import Task
from sim.core.world import World


class SceneEnv(gym.Env):
    """Observations uint8 (H, W, 3) rendered by the world; continuous actions.

    reset(options={"scene": Scene}) or options={"task": Task} starts from that scene; with no
    options it starts from the training task. info["scene"] is the current scene and, when the
    episode ends, info["success"] is R' judged on the episode. Subclasses give the reward and
    say whether the world's end is a termination or a time limit.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}
    ends_by_time_limit: ClassVar[bool] = True

    def __init__(self, world: World, render_mode: str | None = "rgb_array") -> None:
        self.world = world
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Box(0, 255, world.obs_shape, np.uint8)
        self.task: Task = world.train_task()
        self.scene: Scene = self.task.scene
        self.history: list[Scene] = [self.scene]

    def reward(self) -> float:
        """The reward of the current scene."""
        raise NotImplementedError

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        self.task = options.get("task") or self.world.train_task()
        self.scene = options.get("scene") or self.task.scene
        self.history = [self.scene]
        return self.world.render(self.scene), {"scene": self.scene}

    def step(self, action):
        action = np.asarray(action, np.float32).reshape(1, self.world.action_dim)
        self.scene = self.world.step_batch([self.scene], action)[0]
        self.history.append(self.scene)
        ended = self.world.done(self.scene)
        info: dict[str, Any] = {"scene": self.scene}
        if ended:
            info["success"] = self.world.success(self.task, self.history)
        terminated = ended and not self.ends_by_time_limit
        truncated = ended and self.ends_by_time_limit
        return self.world.render(self.scene), self.reward(), terminated, truncated, info

    def render(self):
        return self.world.render(self.scene)
