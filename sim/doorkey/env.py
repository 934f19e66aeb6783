"""`dfa/DoorKey-v0`: the DoorKey world as a minigrid environment.

The episode runs on minigrid's own machinery (MiniGridEnv.step, Grid, WorldObj) with this
world's objects; observations are the full grid rendered at 3 px per cell.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from minigrid.core.mission import MissionSpace
from minigrid.core.world_object import Key
from minigrid.minigrid_env import MiniGridEnv

from sim.core import Obj, Scene, Task
from sim.doorkey.layout import GRID, HORIZON, N_ACTIONS, SIZE_PX, TILE_PX, agent_tuple, parse
from sim.doorkey.objects import AnyKeyDoor, build_grid
from sim.doorkey.world import DoorKeyWorld


class DoorKeyEnv(MiniGridEnv):
    """Observations uint8 (36, 36, 3); actions Discrete(6): left, right, forward, pickup, drop,
    toggle; 35 steps.

    reset(options={"scene": Scene}) or options={"task": Task} starts from that scene (any
    state, mid-episode ones included); with no options, from the training task. Reward:
    minigrid's (1 - 0.9 t / 35 on reaching the goal, else 0). info["scene"] is the current
    Scene; info["success"] is R' judged on the episode once it ends.
    """

    # rgb_array only: the frame is the observation (and no window is opened by check_env)
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = "rgb_array") -> None:
        super().__init__(
            mission_space=MissionSpace(mission_func=lambda: "reach the goal"),
            grid_size=GRID,
            max_steps=HORIZON,
            see_through_walls=True,
            render_mode=render_mode,
            highlight=False,
            tile_size=TILE_PX,
        )
        self.world = DoorKeyWorld()
        self.observation_space = spaces.Box(0, 255, (SIZE_PX, SIZE_PX, 3), np.uint8)
        self.action_space = spaces.Discrete(N_ACTIONS)
        self.task: Task = self.world.train_task()
        self._start: Scene = self.task.scene
        self._key_pos: tuple[float, ...] = self._start.obj("key").pos  # last cell on the floor
        self.history: list[Scene] = [self._start]

    # -- minigrid hooks -----------------------------------------------------------------------
    def _gen_grid(self, width: int, height: int) -> None:
        st = parse(self._start)
        self.grid = build_grid(st)
        self.agent_pos = st.agent
        self.agent_dir = st.dir

    def gen_obs(self) -> np.ndarray:
        """The observation: the full grid, uint8 (36, 36, 3)."""
        return self.get_frame(highlight=False, tile_size=TILE_PX)

    # -- gymnasium ----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        options = options or {}
        self.task = options.get("task") or self.world.train_task()
        self._start = options.get("scene") or self.task.scene
        super().reset(seed=seed)  # builds the grid through _gen_grid
        st = parse(self._start)
        self._key_pos = self._start.obj("key").pos
        if st.carrying:
            self.carrying = Key(self._start.obj("key").value("colour"))  # type: ignore[assignment]
        self.step_count = st.t
        self.history = [self._read_scene()]
        return self.gen_obs(), {"scene": self.scene}

    def step(self, action):
        assert self.action_space.contains(action), f"action must be in 0..5, got {action!r}"
        obs, reward, terminated, truncated, _ = super().step(int(action))
        scene = self._read_scene()
        self.history.append(scene)
        info: dict[str, Any] = {"scene": scene}
        if terminated or truncated:
            info["success"] = self.world.success(self.task, self.history)
        return obs, float(reward), terminated, truncated, info

    # -- the current state as a Scene ---------------------------------------------------------
    @property
    def scene(self) -> Scene:
        """The current state as a Scene value."""
        return self.history[-1]

    def _read_scene(self) -> Scene:
        """The minigrid state as a Scene (colours and latent lava cells from the start)."""
        start = self._start
        key_obj = start.obj("key")
        door_state = 0
        for j in range(GRID):
            for i in range(GRID):
                cell = self.grid.get(i, j)
                if cell is None:
                    continue
                if cell.type == "key":
                    self._key_pos = (float(i), float(j))
                elif isinstance(cell, AnyKeyDoor):
                    door_state = cell.encode()[2]
        objects = (Obj(key_obj.slot, True, key_obj.values, self._key_pos), *start.objects[1:])
        col, row = (int(v) for v in self.agent_pos)
        agent = agent_tuple(
            col, row, self.agent_dir, self.carrying is not None, door_state, self.step_count
        )
        return Scene(start.world, objects, agent)
