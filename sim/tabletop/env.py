"""`dfa/Tabletop-v0`: the tabletop pick-and-place world as a gymnasium environment."""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from sim.core.env import SceneEnv
from sim.tabletop.tasks import VIEW_HALF_M
from sim.tabletop.world import TabletopWorld


class TabletopEnv(SceneEnv):
    """Observations uint8 (80, 80, 3); actions float32 (4,) = (pick_x, pick_y, place_x,
    place_y) in [-0.4, 0.4] metres; one step per episode, which then terminates.

    Reward: minus the distance (m) from the object's centre to the goal's after the primitive.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 2}
    ends_by_time_limit: ClassVar[bool] = False

    def __init__(self, render_mode: str | None = "rgb_array", world: TabletopWorld | None = None):
        super().__init__(world or TabletopWorld(), render_mode)
        self.action_space = gym.spaces.Box(-VIEW_HALF_M, VIEW_HALF_M, (4,), np.float32)

    def reward(self) -> float:
        o, g = self.scene.obj("object").pos, self.scene.obj("goal").pos
        return -float(np.hypot(o[0] - g[0], o[1] - g[1]))
