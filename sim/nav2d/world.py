"""nav2d: a white agent goes to a coloured, shaped goal in a black arena, maybe past a
distractor (a 36x36 numpy renderer, no physics).

Concepts  goal: colour (red, green, blue, yellow) x shape (X, square, triangle, diamond);
          distractor: presence, colour, shape. Objects sit on the four corners (±5, ±5);
          the agent starts on a corner or one of four points inside (tasks.STARTS).
Actions   (dx, dy) in [-1, 1]^2 per step, 20 steps.
Shifts    object_ti / object_tr: the goal's colour or shape changed (R' does not / does care);
          distractor_ti / distractor_tr: a distractor off the path (R' ignores it / says keep
          clear); other: the goal on the bottom-left corner, which training never uses.
Success   within 1 of the goal after the last step, never within 2 of an avoided distractor.

Files: concepts.py (the space), render.py, dynamics.py (steps and success), expert.py,
tasks.py (training layouts, shifts, fresh tasks, placements).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from sim.core import Benchmark, Cloning, Obj, Scene, Task, Trajectory
from sim.core.parameters import SceneParameter, checked, keep_apart
from sim.nav2d import dynamics as D
from sim.nav2d import render as R
from sim.nav2d import tasks as TK
from sim.nav2d.concepts import COLOUR, SPACE
from sim.nav2d.expert import expert_action

CLEARANCE = 2.0  # scene parameters keep the goal, agent and distractor this far apart


class Nav2DWorld(Benchmark):
    """Go to the goal in 20 steps of (dx, dy) in [-1, 1]^2. Agent state: (x, y, t)."""

    name = TK.WORLD
    space = SPACE
    horizon = D.HORIZON
    obs_shape = (R.SIZE_PX, R.SIZE_PX, 3)
    discrete = False
    action_dim = 2
    epsilon = 0.2
    lossless_frames = True
    demo_input = "waypoints"
    description = "The robot is the white disc; it should drive to the goal."
    image_extent = (-R.ARENA, R.ARENA, -R.ARENA, R.ARENA)
    action_names = ("dx", "dy")
    # one expert demonstration per training layout, 40 gradient steps each (the paper's 10
    # demonstrations get 400)
    cloning = Cloning(demonstrations=len(TK.TRAIN_LAYOUTS), steps=40 * len(TK.TRAIN_LAYOUTS))
    # the goal's centre and the agent's start, anywhere their glyph and disc are whole
    scene_parameters = tuple(
        SceneParameter(f"{who}.{axis}", -R.OBJECT_REACH, R.OBJECT_REACH, "units")
        for who in ("goal", "agent")
        for axis in "xy"
    )

    # -- appearance ---------------------------------------------------------------------------
    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        layers = np.stack([self._objects_layer(s.objects) for s in scenes])  # (B, 36, 36, 3)
        agent = np.array([s.agent[:2] for s in scenes], np.float64).reshape(-1, 2)  # (B, 2)
        return R.draw_agents(layers, agent)

    @functools.lru_cache(maxsize=4096)  # noqa: B019 (one world per process)
    def _objects_layer(self, objects: tuple[Obj, ...]) -> np.ndarray:
        """The static part of a frame: every present object, drawn once per distinct layout."""
        shown = [o for o in objects if o.present]
        layer = R.render_objects(
            [R.object_mask(o.pos, o.value("shape")) for o in shown],
            [COLOUR.index(o.value("colour")) for o in shown],
        )
        layer.flags.writeable = False
        return layer

    # -- dynamics -----------------------------------------------------------------------------
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        return D.step_batch(scenes, actions)

    def done(self, scene: Scene) -> bool:
        return D.done(scene)

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        return D.meets_reward(task, scenes)

    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        return expert_action(scene)

    # -- tasks --------------------------------------------------------------------------------
    def train_task(self, seed: int = 0) -> Task:
        return TK.train_task(seed)

    def test_task(self, shift: str, seed: int) -> Task:
        return TK.test_task(shift, seed)

    def intent(self, task: Task) -> str:
        return TK.intent(task)

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        return TK.fresh_tasks(task, n, seed, layouts=layouts, shifted=shifted)

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        return TK.placements(task, slot, demo)

    # -- continuous scene parameters ----------------------------------------------------------
    def with_parameters(self, scene: Scene, values: Sequence[float]) -> Scene:
        """The goal at (goal.x, goal.y), the agent starting at (agent.x, agent.y); refused
        where the goal, the agent and a present distractor are not each CLEARANCE apart (a
        glyph is 2 units wide, the disc 2 across: closer, they overlap)."""
        gx, gy, ax, ay = checked(self.scene_parameters, values)
        points = {"the goal": (gx, gy), "the agent": (ax, ay)}
        d = scene.obj("distractor")
        if d.present:
            points["the distractor"] = d.pos
        keep_apart(points, CLEARANCE, "units")
        g = scene.obj("goal")
        moved = Scene(scene.world, scene.objects, (ax, ay, *scene.agent[2:]))
        return moved.with_obj(Obj(g.slot, g.present, g.values, (gx, gy)))

    def parameters_of(self, scene: Scene) -> tuple[float, ...]:
        g = scene.obj("goal").pos
        return (float(g[0]), float(g[1]), float(scene.agent[0]), float(scene.agent[1]))

    def make_env(self):
        from sim.nav2d.env import Nav2DEnv

        return Nav2DEnv(world=self)
