"""The tabletop: "put the <object> on the <goal>" with one pick-and-place simulated by MuJoCo,
seen by an 80x80 orthographic camera from above.

Concepts  object, goal, distractor0, distractor1 (kind "distractor", optional): shape (29)
          and colour (the configured appearances, 81 by default; sim.tabletop.concepts).
Actions   one primitive per episode: (pick x, pick y, place x, place y) in table metres.
Shifts    object_ti / object_tr: the object's or the goal's shape or colour changed;
          distractor_ti / distractor_tr: one or two distractors in free quadrants (R'
          ignores them / says do not touch them); other: the object or the goal in the
          centre, where no training layout puts anything.
Success   the object's centre within 0.10 m of the goal's after settling, no distractor's
          centre that close, every avoided distractor moved less than 0.02 m.

Scene: Obj.pos is the object's pose on the table, (x, y, z, qw, qx, qy, qz) in metres, z = 0
resting on the table top; it is not part of Phi. agent = (steps taken,). Files: concepts.py,
catalogue.py, shapes.py, meshes.py, colours.py, textures.py, model.py (the MuJoCo model),
render.py, composite.py (frames from cached top views, top_view.py), physics.py (dynamics), pose.py,
view3d.py, tasks.py (layouts, shifts, the expert's targets), env.py.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

import numpy as np

from sim.core import Benchmark, Obj, Reward, Scene, Task, Trajectory, UserError, carrying_shift
from sim.core.parameters import SceneParameter, checked, keep_apart
from sim.tabletop import tasks as TK
from sim.tabletop.colours import ALL_COLOURS, DEFAULT_COLOURS

HORIZON = 1
SUCCESS_RADIUS_M = 0.10  # the object's centre within this of the goal's after settling
AVOID_MOVE_M = 0.02  # an avoided distractor may not move further than this
PARAMETER_REACH_M = 0.3  # scene parameters put centres within [-0.3, 0.3]^2: whole in view
PARAMETER_CLEAR_M = 0.2  # and keep every two present objects' centres this far apart


def _dist_xy(a: Sequence[float], b: Sequence[float]) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))


class TabletopWorld(Benchmark):
    """One primitive per episode: action float32 (4,) = (pick_x, pick_y, place_x, place_y) m.

    colours: the colour concept's instantiations (any of sim.tabletop.colours.ALL_COLOURS).
    compositing: frames composited from cached top views wherever that gives MuJoCo's own
    pixels (sim.tabletop.composite), MuJoCo for every other scene; False: MuJoCo for all.
    MuJoCo is loaded on the first render or step; one model and one GL context serve every
    scene, guarded by a lock (the model is edited in place per scene).
    """

    name = "tabletop"
    horizon = HORIZON
    obs_shape = (80, 80, 3)
    discrete = False
    action_dim = 4
    epsilon = 0.06
    # about 440 single edits and 95,000 pairs: a size-2 search stops at its first valid edit
    search_first_only = True
    search_max_candidates = 20_000  # ~30 s: "no counterfactual" among the most promising
    demo_input = "pick_place"
    description = "A robot arm seen from above should pick up an object and put it on another."
    image_extent = (-TK.VIEW_HALF_M, TK.VIEW_HALF_M, -TK.VIEW_HALF_M, TK.VIEW_HALF_M)
    action_names = ("pick x (m)", "pick y (m)", "place x (m)", "place y (m)")
    appearance_concepts = frozenset({"colour"})  # a material: drawn, never simulated
    simulated = True  # a rollout is a pick and place in MuJoCo
    # where the object and the goal stand on the table (their rotation and height kept)
    scene_parameters = tuple(
        SceneParameter(f"{slot}.{axis}", -PARAMETER_REACH_M, PARAMETER_REACH_M, "m")
        for slot in ("object", "goal")
        for axis in "xy"
    )

    def __init__(
        self, colours: Sequence[str] = DEFAULT_COLOURS, *, compositing: bool = True
    ) -> None:
        unknown = [c for c in colours if c not in ALL_COLOURS]
        if unknown:
            raise UserError(f"unknown colours {unknown}; accepted: {', '.join(ALL_COLOURS)}")
        if len(set(colours)) != len(colours):
            raise UserError(f"colours must be distinct, got {list(colours)}")
        for needed in (TK.TRAIN_OBJECT[1], TK.TRAIN_GOAL[1]):
            if needed not in colours:
                raise UserError(f"colours must include the training colour {needed!r}")
        self.colours = tuple(colours)
        self.space = TK.space(self.colours)
        self._lock = threading.RLock()
        self._sim = None  # (Table, TopCamera, PickPlace), built on first use
        self.compositing = compositing
        self._compositor = None  # sim.tabletop.composite.Compositor, built on first render
        from sim.tabletop.view3d import TabletopView3D

        self.view3d = TabletopView3D(self)

    # -- MuJoCo, lazily -----------------------------------------------------------------------
    def _parts(self):
        with self._lock:
            if self._sim is None:
                from sim.tabletop.model import Table
                from sim.tabletop.physics import PickPlace
                from sim.tabletop.render import TopCamera

                table = Table()
                self._sim = (table, TopCamera(table), PickPlace(table))
            return self._sim

    # -- appearance ---------------------------------------------------------------------------
    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, 80, 80, 3), the top camera's view of each scene."""
        with self._lock:
            camera = self._parts()[1]
            if not self.compositing:
                return camera.render_batch(scenes)
            if self._compositor is None:
                from sim.tabletop.composite import Compositor
                from sim.tabletop.view_store import store_path

                store = store_path(camera.table, camera.size_px)
                self._compositor = Compositor(camera.render_batch, TK.make_scene(), store=store)
            return self._compositor.render_batch(scenes)

    # -- dynamics -----------------------------------------------------------------------------
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        actions = np.asarray(actions, np.float64)
        assert actions.shape == (len(scenes), 4), f"actions must be (B, 4), got {actions.shape}"
        if not np.isfinite(actions).all():
            raise UserError("tabletop actions are pick and place points in metres: finite numbers")
        out = []
        with self._lock:
            pp = self._parts()[2]
            for s, a in zip(scenes, actions, strict=True):
                out.append(s if self.done(s) else pp.run(s, a)[0])
        return out

    def step_with_frames(self, scene: Scene, action: np.ndarray, *, every: int = 5):
        """One primitive with the objects' poses recorded every `every` physics steps.

        Returns (physics.Frames, scene after settling).
        """
        with self._lock:
            after, frames = self._parts()[2].run(scene, np.asarray(action, float), every=every)
        return frames, after

    def done(self, scene: Scene) -> bool:
        return bool(scene.agent) and scene.agent[0] >= HORIZON

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        return on_goal(task.reward, scenes)

    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        """Pick at the object's centre, place at the goal's centre."""
        o, g = scene.obj("object").pos, scene.obj("goal").pos
        return np.array([o[0], o[1], g[0], g[1]], np.float32)

    # -- tasks --------------------------------------------------------------------------------
    def train_task(self, seed: int = 0) -> Task:
        return TK.train_task(seed)

    def test_task(self, shift: str, seed: int) -> Task:
        return TK.test_task(shift, seed, self.colours)

    def intent(self, task: Task) -> str:
        return TK.intent(task)

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        draw = carrying_shift(self.space, task) if shifted else None
        return TK.fresh_tasks(task, n, seed, layouts, draw=draw)

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        return TK.placements(task, slot, demo)

    # -- continuous scene parameters ----------------------------------------------------------
    def with_parameters(self, scene: Scene, values: Sequence[float]) -> Scene:
        """The object's centre at (object.x, object.y) and the goal's at (goal.x, goal.y) m;
        refused where two present objects' centres (distractors too) come closer than
        PARAMETER_CLEAR_M (the largest footprints are about 0.17 m across)."""
        ox, oy, gx, gy = checked(self.scene_parameters, values)
        points = {"the object": (ox, oy), "the goal": (gx, gy)}
        for slot in TK.DISTRACTORS:
            d = scene.obj(slot)
            if d.present:
                points[slot] = d.pos[:2]
        keep_apart(points, PARAMETER_CLEAR_M, "m")
        for slot, (x, y) in (("object", (ox, oy)), ("goal", (gx, gy))):
            o = scene.obj(slot)
            scene = scene.with_obj(Obj(o.slot, o.present, o.values, (x, y, *o.pos[2:])))
        return scene

    def parameters_of(self, scene: Scene) -> tuple[float, ...]:
        o, g = scene.obj("object").pos, scene.obj("goal").pos
        return (float(o[0]), float(o[1]), float(g[0]), float(g[1]))

    def make_env(self):
        from sim.tabletop.env import TabletopEnv

        return TabletopEnv(world=self)


def on_goal(reward: Reward, scenes: Sequence[Scene]) -> bool:
    """R' on a rollout: after the last scene the object's centre is within SUCCESS_RADIUS_M of
    the goal's, no present distractor's centre is, and every avoided distractor stayed put."""
    first, final = scenes[0], scenes[-1]
    goal = final.obj("goal").pos
    if _dist_xy(final.obj("object").pos, goal) >= SUCCESS_RADIUS_M:
        return False
    for slot in TK.DISTRACTORS:
        d = final.obj(slot)
        if d.present and _dist_xy(d.pos, goal) < SUCCESS_RADIUS_M:
            return False
    for slot in reward.avoid:
        d0, d1 = first.obj(slot), final.obj(slot)
        if d0.present and _dist_xy(d0.pos, d1.pos) > AVOID_MOVE_M:
            return False
    return True
