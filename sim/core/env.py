"""A World as a gymnasium environment: reset to any scene or task, step, render."""

from __future__ import annotations

from typing import Any, ClassVar, cast

import gymnasium as gym
import numpy as np

from sim.core.scene import Scene
from sim.core.task import Task
from sim.core.world import Benchmark, World


class SceneEnv(gym.Env):
    """Observations uint8 (H, W, 3) rendered by the world; its actions (Discrete(n) for a
    discrete world, else float32 (A,): subclasses narrow the bounds).

    reset(options={"scene": Scene}) or options={"task": Task} starts from that scene; with no
    options it starts from the training task (a Benchmark's) or the world's sample scene.
    info["scene"] is the current scene and, when the episode ends, info["success"] is R' judged
    on the episode. Reward: 1.0 on the step an episode ends in success (subclasses may shape
    it); `ends_by_time_limit` says whether the world's end is a time limit or a termination.
    """

    # an instance variable on gymnasium.Env
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 10}
    ends_by_time_limit: ClassVar[bool] = True

    def __init__(self, world: World, render_mode: str | None = "rgb_array") -> None:
        self.world = world
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Box(0, 255, world.obs_shape, np.uint8)
        if world.discrete:
            self.action_space = gym.spaces.Discrete(world.action_dim)
        else:
            self.action_space = gym.spaces.Box(-np.inf, np.inf, (world.action_dim,), np.float32)
        self.task: Task = self._default_task(0)
        self.scene: Scene = self.task.scene
        self.history: list[Scene] = [self.scene]

    def _default_task(self, seed: int) -> Task:
        w = self.world
        if w.benchmark:
            return cast(Benchmark, w).train_task()
        return w.task_for(w.sample_scene(seed))

    def reward(self) -> float:
        """The reward of the current scene (the episode's history is `self.history`)."""
        ended = self.world.done(self.scene)
        return float(ended and self.world.success(self.task, self.history))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        self.task = options.get("task") or self._default_task(seed or 0)
        self.scene = options.get("scene") or self.task.scene
        self.history = [self.scene]
        return self.world.render(self.scene), {"scene": self.scene}

    def step(self, action):
        if self.world.discrete:
            action = np.asarray([int(action)], np.int64)
        else:
            action = np.asarray(action, np.float32).reshape(1, self.world.action_dim)
        self.scene = self.world.step_batch([self.scene], action)[0]
        self.history.append(self.scene)
        ended = self.world.done(self.scene) or len(self.history) > self.world.horizon
        info: dict[str, Any] = {"scene": self.scene}
        if ended:
            info["success"] = self.world.success(self.task, self.history)
        terminated = ended and not self.ends_by_time_limit
        truncated = ended and self.ends_by_time_limit
        return self.world.render(self.scene), self.reward(), terminated, truncated, info

    def render(self):
        return self.world.render(self.scene)
