"""A MuJoCo environment as a world: the generic layer under the Fetch (and any other MuJoCo)
worlds.

A package's environment comes in through a few hooks (`open_env`, `env_step`, `env_success`,
`slot_specs`, and where the environment keeps state outside MuJoCo's, `env_state`/
`set_env_state`; where it is not a gymnasium MujocoEnv, `physics`, `camera` and
`drawn_groups`); everything else is here:

Scene     agent = (t, success, *environment state, *physics state): `success` the environment's
          own verdict after its last step (1.0 or 0.0); the environment state what its step
          reads beside MuJoCo's (Fetch: its goal; robosuite: its gripper's commanded opening),
          a fixed number of floats; the physics state MuJoCo's full integration state
          (mj_getState, mjSTATE_INTEGRATION): restoring both and stepping through the
          environment's own step gives the environment's own rollout. Each slot's Obj holds its
          colour (a palette name) and, for bodies, where it is (x, y, z); a distractor's pos is
          where it stands once present.
Render    the environment's own camera (the pixels of its `render()`: a free camera set as its
          default_camera_config, or one of the model's cameras by name), drawing the geom
          groups it draws, each slot painted in the scene's colour
Dynamics  the environment's own step (controller, frame skip, callbacks), one scene at a time
          on one MjData: restore, step, read back
Success   the environment's own (e.g. Fetch's info["is_success"]) after the last step: kept in
          the scene as its step reported it (its sites lag one physics step behind the state)
Tasks     sim.mjworld.tasks, from where the package's tasks start (`reset_scene`) and what its
          table offers (`workspace`, `keep_clear`, `way`, `grip_pos`)

Distractors are spare free blocks added to the model once (MjSpec), parked out of view while
absent, where they touch nothing and gravity does not move them (so the rest steps exactly as in
the environment's own model); a present distractor starts where its Obj.pos says.
"""

from __future__ import annotations

import abc
import atexit
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim.core import (
    RGB,
    Benchmark,
    Concept,
    ConceptSpace,
    Obj,
    Paints,
    Scene,
    Slot,
    Task,
    Trajectory,
    UserError,
)

ENV_STATE_AT = 2  # agent[:2] = (t, success); agent[2:head] = the environment's own state
AVOID_M = 0.02  # an avoided distractor may not move further than this
COLOUR = "colour"
STATE_BITS = None  # mujoco.mjtState.mjSTATE_INTEGRATION, read when MuJoCo is imported


@dataclass(frozen=True)
class SlotSpec:
    """One slot of a MuJoCo world: a body (its visual geoms) or a site, by name in the model."""

    name: str
    body: str | None = None
    site: str | None = None
    moves: bool = False
    """Its place is read from the physics state (a body with a free joint)."""


class MujocoWorld(Benchmark):
    """A MuJoCo environment as a World; see the module docstring. Subclasses give the hooks."""

    discrete = False
    lossless_frames = False
    demo_input = "file"
    simulated = True  # every step is the environment's own MuJoCo step
    counterfactual = "succeeds"  # closed-loop control: judged by the environment's success
    distractors: tuple[str, ...] = ("distractor0",)
    slot_specs: tuple[SlotSpec, ...] = ()
    camera: dict | str = {}
    """The camera frames are drawn from: a free camera (distance, azimuth, elevation, lookat),
    as a gymnasium MujocoEnv's default_camera_config gives it, or a camera of the model by
    name."""
    extra_views: tuple[dict | str, ...] = ()
    """Further cameras (as `camera`), each drawn size_px square to the right of the
    environment's own in every frame: a view that settles what the first leaves open."""
    workspace = None
    """A sim.mjworld.tasks.Workspace: where distractors may stand, what the shifts recolour."""
    drawn_groups: tuple[int, ...] = (0, 1, 2)
    """The geom groups the environment's camera draws (MuJoCo's default: 0, 1 and 2); a slot's
    visual geoms are those in these groups, and a distractor's block is in the first."""
    effector: str | None = None
    """The body of the end effector (the gripper): the 3D view (sim.mjworld.view3d) draws it
    and every body below it, and an action as its motion; None: no end effector drawn."""

    def __init__(self, name: str, *, horizon: int, action_dim: int, size_px: int) -> None:
        self.name, self.horizon, self.action_dim = name, horizon, action_dim
        self.obs_shape = (size_px, size_px * (1 + len(self.extra_views)), 3)
        self.size_px = size_px
        self._lock = threading.RLock()
        self._env = None
        self._camera = None  # (mujoco.Renderer, [camera per view], MjvOption), on first render
        self._looks: dict = {}
        env = self._open()  # the concept space is read from the model
        self.built = {s: self._looks[s].colour for s in self._looks}
        from sim.mjworld.model import AS_BUILT, PALETTE

        self.paints = Paints(COLOUR, dict(PALETTE))  # any rgba: a geom's colour is its rgba

        slots = []
        for spec in self.all_slots():
            colours = tuple(PALETTE) + ((AS_BUILT,) if self.built[spec.name] == AS_BUILT else ())
            optional = spec.name in self.distractors
            slots.append(
                Slot(spec.name, (Concept(COLOUR, colours),), optional, "distractor" * optional)
            )
        self.space = ConceptSpace(tuple(slots))
        from sim.mjworld.tasks import offered_shifts

        self.shifts = offered_shifts(self.workspace)
        self.nstate = len(self._state(env))
        self.head = ENV_STATE_AT + len(self.env_state(env))  # agent[head:] = the physics state
        from sim.mjworld.view3d import MujocoView3D

        self.view3d = MujocoView3D(self)  # its meshes read from the model when first asked for

    def all_slots(self) -> tuple[SlotSpec, ...]:
        """The package's slots, then the distractors (each a body that moves)."""
        return (*self.slot_specs, *(SlotSpec(d, body=d, moves=True) for d in self.distractors))

    # -- hooks ----------------------------------------------------------------------------------
    @abc.abstractmethod
    def open_env(self, add_bodies: Callable) -> object:
        """The environment, built with `add_bodies(spec: mujoco.MjSpec)` applied to its model
        before it is compiled, rendering rgb_array frames of size_px x size_px."""

    @abc.abstractmethod
    def env_step(self, env, action: np.ndarray) -> bool:
        """One step of the environment's own (its controller, frame skip and callbacks); its
        own success after it."""

    @abc.abstractmethod
    def env_success(self, env) -> bool:
        """The environment's own success in its current state (for a scene no step made)."""

    def env_state(self, env) -> np.ndarray:
        """float (n,), the same n for every state: what the environment's step reads beside
        MuJoCo's state (e.g. its goal); none by default."""
        return np.zeros(0)

    def set_env_state(self, env, state: np.ndarray) -> None:
        """Put back what `env_state` read."""

    @abc.abstractmethod
    def reset_scene(self, seed: int, *, unseen: bool = False) -> Scene:
        """A scene from the environment's own reset, seeded: default looks, no distractor;
        `unseen`: its object where no training task puts it."""

    @abc.abstractmethod
    def keep_clear(self, scene: Scene) -> list[np.ndarray]:
        """The (x, y) an added distractor keeps clear of (objects, goal, gripper's start)."""

    def way(self, scene: Scene) -> tuple[np.ndarray, np.ndarray] | None:
        """(from, to) (x, y) of what the task carries (a distractor in the way stands beside
        it); None: nothing is carried across the table."""
        return None

    @abc.abstractmethod
    def grip_pos(self, env) -> np.ndarray:
        """float (3,): the gripper where the environment is now."""

    def effector_action(self, grip: np.ndarray, to: np.ndarray, close: bool) -> np.ndarray:
        """The action that moves the end effector from `grip` toward `to` (float (3,) each),
        the fingers closed or open: what clicked waypoints are followed with (a world that
        gives it declares demo_input "effector")."""
        raise UserError(f"{self.name} takes no clicked waypoints")

    def effector_waypoint(self, scene, u, v, last):
        from sim.mjworld import clicks

        return clicks.waypoint(self, scene, u, v, last)

    def follow(self, task, waypoints):
        from sim.mjworld import clicks

        return clicks.follow(self, task, waypoints)

    def physics(self, env) -> tuple:
        """(mujoco.MjModel, mujoco.MjData) the environment steps (a gymnasium MujocoEnv's own
        by default)."""
        u = env.unwrapped
        return u.model, u.data

    # -- the environment --------------------------------------------------------------------
    def _open(self):
        with self._lock:
            if self._env is None:
                import mujoco

                from sim.mjworld import model as M

                global STATE_BITS
                STATE_BITS = mujoco.mjtState.mjSTATE_INTEGRATION
                group = self.drawn_groups[0]
                env = self.open_env(lambda s: M.add_distractors(s, self.distractors, group=group))
                m, _ = self.physics(env)
                for spec in self.all_slots():
                    self._looks[spec.name] = M.slot_looks(
                        m, body=spec.body, site=spec.site, groups=self.drawn_groups
                    )
                self._env = env
            return self._env

    def _state(self, env) -> np.ndarray:
        import mujoco

        m, d = self.physics(env)
        state = np.empty(mujoco.mj_stateSize(m, STATE_BITS))
        mujoco.mj_getState(m, d, state, STATE_BITS)
        return state

    def env_state_of(self, scene: Scene) -> np.ndarray:
        """float (n,): the environment's own state in `scene` (see env_state)."""
        return np.asarray(scene.agent[ENV_STATE_AT : self.head], float)

    def restore(self, scene: Scene):
        """Put `scene` into the environment (its states, distractors, colours) with every
        derived quantity computed from the state (mj_forward), as the environment's render()
        leaves it before the next step of an image policy's loop; returns the environment."""
        import mujoco

        from sim.mjworld import model as M

        env = self._open()
        model, data = self.physics(env)
        state = np.asarray(scene.agent[self.head :], float)
        if len(state) != self.nstate:
            raise UserError(
                f"{self.name}: a scene's physics state has {len(state)} numbers, not "
                f"{self.nstate} (a scene of another model?)"
            )
        mujoco.mj_setState(model, data, state, STATE_BITS)
        for k, slot in enumerate(self.distractors):
            o = scene.obj(slot)
            joint = model.joint(f"{slot}:joint")
            qa, va = joint.qposadr[0], joint.dofadr[0]
            parked = np.abs(data.qpos[qa : qa + 3] - M.park_pos(k)).max() < 0.01
            M.take_part(model, self._looks[slot], o.present)
            if not o.present:
                data.qpos[qa : qa + 7] = [*M.park_pos(k), 1.0, 0.0, 0.0, 0.0]
                data.qvel[va : va + 6] = 0.0
            elif parked:  # brought into the workspace: it starts where the scene says
                data.qpos[qa : qa + 7] = [*o.pos[:3], 1.0, 0.0, 0.0, 0.0]
                data.qvel[va : va + 6] = 0.0
        self.set_env_state(env, self.env_state_of(scene))
        for slot, looks in self._looks.items():
            M.paint(model, looks, scene.obj(slot).value(COLOUR))
        mujoco.mj_forward(model, data)
        return env

    def scene_of(self, env, t: int, like: Scene, success: bool | None = None) -> Scene:
        """The environment's current state as a scene: `like`'s looks, the places as they are;
        `success` as its last step said (None: judged on the state as it is)."""
        _, data = self.physics(env)
        objects = []
        for spec in self.all_slots():
            o = like.obj(spec.name)
            pos = o.pos
            if spec.moves and (o.present or spec.name not in self.distractors):
                pos = tuple(round(float(v), 9) for v in data.body(spec.body).xpos)
            objects.append(Obj(o.slot, o.present, o.values, pos))
        own = map(float, self.env_state(env))
        if success is None:
            success = self.env_success(env)
        state = map(float, self._state(env))
        return Scene(self.name, tuple(objects), (float(t), float(success), *own, *state))

    # -- appearance ---------------------------------------------------------------------------
    def before_render(self, env) -> None:
        """What the environment does to its model before it draws (e.g. Fetch's target marker
        moved to the goal); nothing by default."""

    def _renderer(self):
        """One mujoco.Renderer on the environment's model, its cameras (the environment's own
        first, then `extra_views`; each a free one set as the environment's
        default_camera_config sets its own, or the model's camera of that name) and the geom
        groups it draws: the first view's pixels are those of its render()."""
        if self._camera is None:
            import mujoco

            from sim.mjworld.gl import free_camera, release_egl

            model, _ = self.physics(self._open())
            renderer = mujoco.Renderer(model, self.size_px, self.size_px)
            release_egl()  # the constructor left the context current in this thread
            atexit.register(renderer.close)  # before EGL itself is let go at exit
            cams = [free_camera(c) for c in (self.camera, *self.extra_views)]
            option = mujoco.MjvOption()
            option.geomgroup[:] = [
                int(g in self.drawn_groups) for g in range(len(option.geomgroup))
            ]
            self._camera = (renderer, cams, option)
        return self._camera

    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3): the environment's camera on each scene (and its extra views to
        the right of it, W = size_px times the number of views)."""
        return self.render_painted(scenes, [{}] * len(scenes))

    def render_painted(
        self, scenes: Sequence[Scene], paints: Sequence[dict[str, RGB]]
    ) -> np.ndarray:
        """render_batch with the slots in paints[b] drawn in those colours (rgb in [0, 1])."""
        from sim.mjworld import model as M
        from sim.mjworld.gl import current

        assert len(paints) == len(scenes), "one paint mapping per scene"
        size = self.size_px
        out = np.empty((len(scenes), *self.obs_shape), np.uint8)
        view = np.empty((size, size, 3), np.uint8)
        with self._lock:
            renderer, cams, option = self._renderer()
            with current(renderer):
                for b, scene in enumerate(scenes):
                    env = self.restore(scene)
                    for slot, rgb in paints[b].items():  # drawn from the model's rgba
                        M.paint(self.physics(env)[0], self._looks[slot], rgb)
                    self.before_render(env)
                    for k, cam in enumerate(cams):
                        renderer.update_scene(self.physics(env)[1], camera=cam, scene_option=option)
                        renderer.render(out=view)
                        out[b, :, k * size : (k + 1) * size] = view
        return out

    # -- dynamics -----------------------------------------------------------------------------
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        actions = np.asarray(actions, np.float64).reshape(len(scenes), self.action_dim)
        if not np.isfinite(actions).all():
            raise UserError(f"{self.name}: actions must be finite numbers")
        out = []
        with self._lock:
            for scene, a in zip(scenes, actions, strict=True):
                if self.done(scene):
                    out.append(scene)
                    continue
                env = self.restore(scene)
                success = self.env_step(env, a)
                out.append(self.scene_of(env, int(scene.agent[0]) + 1, scene, success))
        return out

    def done(self, scene: Scene) -> bool:
        return scene.agent[0] >= self.horizon

    def succeeds(self, scene: Scene) -> bool:
        """The environment's own success in `scene` (as the step that made it said)."""
        return scene.agent[1] == 1.0

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        """The environment's success on the last state; every distractor R' says to avoid
        moved less than AVOID_M."""
        first, last = scenes[0], scenes[-1]
        for slot in task.reward.avoid:
            a, b = first.obj(slot), last.obj(slot)
            if a.present and np.linalg.norm(np.subtract(a.pos[:3], b.pos[:3])) > AVOID_M:
                return False
        return self.succeeds(last)

    # -- tasks (sim.mjworld.tasks) ------------------------------------------------------------
    def train_task(self, seed: int = 0) -> Task:
        from sim.mjworld import tasks as MT

        return MT.train_task(self, seed)

    def test_task(self, shift: str, seed: int) -> Task:
        from sim.mjworld import tasks as MT

        return MT.test_task(self, shift, seed)

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        from sim.mjworld import tasks as MT

        return MT.fresh_tasks(self, task, n, seed, layouts=layouts, shifted=shifted)

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        from sim.mjworld import tasks as MT

        return MT.placements(self, task, demo)
