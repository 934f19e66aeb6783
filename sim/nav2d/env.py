"""`dfa/Nav2D-v0`: the 2D navigation world as a gymnasium environment."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sim.core.env import SceneEnv
from sim.nav2d.world import Nav2DWorld


class Nav2DEnv(SceneEnv):
    """Observations uint8 (36, 36, 3); actions float32 (2,) in [-1, 1]; 20 steps, then a time
    limit. Reward: minus the distance to the goal."""

    def __init__(self, render_mode: str | None = "rgb_array", world: Nav2DWorld | None = None):
        super().__init__(world or Nav2DWorld(), render_mode)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reward(self) -> float:
        gx, gy = self.scene.obj("goal").pos
        return -float(np.hypot(self.scene.agent[0] - gx, self.scene.agent[1] - gy))
