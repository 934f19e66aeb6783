"""nav2d's scripted expert: straight to the goal, arriving exactly at the last step."""

from __future__ import annotations

import numpy as np

from sim.core import Scene
from sim.nav2d.dynamics import HORIZON


def expert_action(scene: Scene) -> np.ndarray:
    """(goal - pos) / steps left, clipped to [-1, 1]^2: float32 (2,)."""
    x, y, t = scene.agent
    left = max(HORIZON - t, 1.0)
    gx, gy = scene.obj("goal").pos
    return np.clip(np.array([(gx - x) / left, (gy - y) / left], np.float32), -1, 1)
