"""DoorKey: pick up the key, open the door, reach the goal on a 12x12 MiniGrid grid (a
minigrid.MiniGridEnv subclass, 3 px tiles, the agent drawn white).

Concepts  key, door, goal: colour (red, green, blue, yellow); lava0..lava2 (kind "lava"):
          presence, colour (orange, pink). Any key opens any door.
Actions   6 discrete: left, right, forward, pick up, drop, toggle; 35 steps.
Shifts    object_ti / object_tr: the key's, door's or goal's colour changed; distractor_ti /
          distractor_tr: lava tiles by the door, off the path (R' ignores them / says keep
          clear); other: the key or the door on a row no training layout has for it.
Success   on the goal by the last state, never on or next to a lava tile R' avoids.

Files: concepts.py (the space), layout.py (the grid and a scene's integer state), render.py,
objects.py, dynamics.py, expert.py (breadth-first search), tasks.py, env.py.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim.core import Benchmark, Cloning, Key, Obj, Scene, Task, Trajectory
from sim.core.parameters import InvalidScene, SceneParameter, checked
from sim.doorkey import layout as L
from sim.doorkey import tasks
from sim.doorkey.dynamics import step_scene
from sim.doorkey.expert import plan
from sim.doorkey.layout import HORIZON, LEFT, N_ACTIONS, SIZE_PX, SPACE, WORLD, parse
from sim.doorkey.render import Renderer


class DoorKeyWorld(Benchmark):
    """Key, door, goal and up to three lava tiles on a 12x12 grid; 6 discrete actions, 35 steps.

    Scene.agent = (col, row, dir, carrying, door, t); see sim.doorkey.layout for the layout.
    """

    name = WORLD
    space = SPACE
    horizon = HORIZON
    obs_shape = (SIZE_PX, SIZE_PX, 3)
    discrete = True
    action_dim = N_ACTIONS
    epsilon = 0.0
    # one demonstration on each training layout, 40 gradient steps a demonstration as the
    # paper's ten get (30 layouts: 1,200 steps): every layout solved
    cloning = Cloning(demonstrations=len(tasks.TRAIN_LAYOUTS), steps=40 * len(tasks.TRAIN_LAYOUTS))
    lossless_frames = True  # gridworld frames are recorded without lossy compression
    demo_input = "keys"
    description = (
        "The robot is the white triangle; it should pick up the key, open the door and reach "
        "the goal square."
    )
    keys = (
        Key("turn left", "arrowleft", L.LEFT),
        Key("turn right", "arrowright", L.RIGHT),
        Key("forward", "arrowup", L.FORWARD),
        Key("pick up", "P", L.PICKUP),
        Key("drop", "D", L.DROP),
        Key("toggle", "T", L.TOGGLE),
    )
    idle_action = L.LEFT  # the steps left after the goal turn in place
    action_names = tuple(k.label for k in sorted(keys, key=lambda k: k.action))
    # the rows of the key, the door and the goal (their columns are the layout's); a value
    # is projected onto the nearest row
    scene_parameters = tuple(
        SceneParameter(f"{slot}.row", float(L.ROWS[0]), float(L.ROWS[-1]), "cells")
        for slot in L.OBJ_SLOTS
    )

    def __init__(self) -> None:
        self._renderer = Renderer()

    # -- appearance ---------------------------------------------------------------------------
    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, 36, 36, 3): minigrid's full-grid render at 3 px per cell, white agent."""
        return self._renderer.render_states([parse(s) for s in scenes])

    # -- dynamics -----------------------------------------------------------------------------
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        """actions: int (B,) in [0, 6). Finished scenes come back unchanged."""
        actions = np.asarray(actions)
        assert actions.shape == (len(scenes),), f"actions must be (B,) ints, got {actions.shape}"
        return [step_scene(s, a) for s, a in zip(scenes, actions.tolist(), strict=True)]

    def done(self, scene: Scene) -> bool:
        return parse(scene).done()

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        """On the goal by the last state, and never on or next to a lava tile R' avoids."""
        final = parse(scenes[-1])
        if final.agent != final.goal:
            return False
        for slot in task.reward.avoid:
            o = scenes[0].obj(slot)
            if o.present:
                cell = (int(o.pos[0]), int(o.pos[1]))
                if any(parse(s).agent in tasks.neighbours(cell) for s in scenes):
                    return False
        return True

    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        """First action of a shortest plan (key, door, goal): int64, shape (). LEFT when
        there is nothing left to do (finished, or no way to the goal)."""
        p = plan(parse(scene))
        return np.asarray(p[0] if p else LEFT, np.int64)  # () int64

    # -- tasks --------------------------------------------------------------------------------
    def train_task(self, seed: int = 0) -> Task:
        return tasks.train_task(seed)

    def test_task(self, shift: str, seed: int) -> Task:
        return tasks.shifted_task(shift, seed)

    def intent(self, task: Task) -> str:
        return tasks.intent(task)

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        return tasks.fresh_tasks(task, n, seed, layouts, shifted=shifted)

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        return tasks.placements(task, slot, demo)

    def in_the_way(self, task: Task, slot: str) -> list[tuple[float, ...]]:
        return tasks.in_the_way(task, slot)

    # -- continuous scene parameters ----------------------------------------------------------
    def with_parameters(self, scene: Scene, values: Sequence[float]) -> Scene:
        """The key, door and goal on the rows nearest `values`, in their own columns; refused
        where one would stand on a present lava tile. The expert may be unable to solve the
        layout in time (a search counts no failure there)."""
        rows = [int(np.floor(v + 0.5)) for v in checked(self.scene_parameters, values)]
        lava = {tuple(o.pos[:2]) for o in scene.objects if o.present and o.slot in L.LAVA_SLOTS}
        for slot, row in zip(L.OBJ_SLOTS, rows, strict=True):
            o = scene.obj(slot)
            cell = (float(L.COLUMNS[slot]), float(row))
            if cell in lava:
                raise InvalidScene(f"the {slot} on row {row} would stand on lava")
            scene = scene.with_obj(Obj(o.slot, o.present, o.values, cell))
        return scene

    def parameters_of(self, scene: Scene) -> tuple[float, ...]:
        return tuple(float(scene.obj(slot).pos[1]) for slot in L.OBJ_SLOTS)

    def make_env(self):
        from sim.doorkey.env import DoorKeyEnv

        return DoorKeyEnv()
