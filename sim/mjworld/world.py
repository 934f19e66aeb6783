"""A MuJoCo environment as a world: the generic layer under the Fetch (and any other MuJoCo)
worlds.

A package's environment comes in through a few hooks (`open_env`, `env_step`, `env_success`,
`goal`/`set_goal`, `slot_specs`); everything else is here:

Scene     agent = (t, success, goal x, y, z, *physics state): `success` the environment's own
          verdict after its last step (1.0 or 0.0), the state MuJoCo's full integration
          state (mj_getState, mjSTATE_INTEGRATION): restoring it and stepping through the
          environment's own step gives the environment's own rollout. Each slot's Obj holds its
          colour (a palette name) and, for bodies, where it is (x, y, z); a distractor's pos is
          where it stands once present.
Render    the environment's own camera (the pixels of its `render()`), each slot painted in the
          scene's colour
Dynamics  the environment's own step (controller, frame skip, callbacks), one scene at a time
          on one MjData: restore, step, read back
Success   the environment's own (e.g. Fetch's info["is_success"]) after the last step: kept in
          the scene as its step reported it (its sites lag one physics step behind the state)

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

from sim.core import Benchmark, Concept, ConceptSpace, Obj, Scene, Slot, Task, UserError

GOAL = slice(2, 5)  # agent[GOAL] = the goal (x, y, z); agent[:2] = (t, success)
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
    distractors: tuple[str, ...] = ("distractor0",)
    slot_specs: tuple[SlotSpec, ...] = ()
    camera: dict = {}
    """The free camera frames are drawn from (distance, azimuth, elevation, lookat), as the
    environment's default_camera_config gives it."""

    def __init__(self, name: str, *, horizon: int, action_dim: int, size_px: int) -> None:
        self.name, self.horizon, self.action_dim = name, horizon, action_dim
        self.obs_shape = (size_px, size_px, 3)
        self.size_px = size_px
        self._lock = threading.RLock()
        self._env = None
        self._camera = None  # (mujoco.Renderer, MjvCamera), made on the first render
        self._looks: dict = {}
        env = self._open()  # the concept space is read from the model
        self.built = {s: self._looks[s].colour for s in self._looks}
        from sim.mjworld.model import AS_BUILT, PALETTE

        slots = []
        for spec in self.all_slots():
            colours = tuple(PALETTE) + ((AS_BUILT,) if self.built[spec.name] == AS_BUILT else ())
            optional = spec.name in self.distractors
            slots.append(
                Slot(spec.name, (Concept(COLOUR, colours),), optional, "distractor" * optional)
            )
        self.space = ConceptSpace(tuple(slots))
        self.nstate = len(self._state(env))
        self.head = GOAL.stop  # agent[head:] = the physics state

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

    @abc.abstractmethod
    def goal(self, env) -> np.ndarray:
        """float (3,): the environment's goal."""

    @abc.abstractmethod
    def set_goal(self, env, goal: np.ndarray) -> None: ...

    # -- the environment --------------------------------------------------------------------
    def _open(self):
        with self._lock:
            if self._env is None:
                import mujoco

                from sim.mjworld import model as M

                global STATE_BITS
                STATE_BITS = mujoco.mjtState.mjSTATE_INTEGRATION
                env = self.open_env(lambda spec: M.add_distractors(spec, self.distractors))
                m = env.unwrapped.model
                for spec in self.all_slots():
                    self._looks[spec.name] = M.slot_looks(m, body=spec.body, site=spec.site)
                self._env = env
            return self._env

    @staticmethod
    def _state(env) -> np.ndarray:
        import mujoco

        u = env.unwrapped
        state = np.empty(mujoco.mj_stateSize(u.model, STATE_BITS))
        mujoco.mj_getState(u.model, u.data, state, STATE_BITS)
        return state

    def goal_of(self, scene: Scene) -> np.ndarray:
        return np.asarray(scene.agent[GOAL], float)

    def restore(self, scene: Scene):
        """Put `scene` into the environment (state, goal, distractors, colours) with every
        derived quantity computed from the state (mj_forward), as the environment's render()
        leaves it before the next step of an image policy's loop; returns the environment."""
        import mujoco

        from sim.mjworld import model as M

        env = self._open()
        u = env.unwrapped
        state = np.asarray(scene.agent[self.head :], float)
        if len(state) != self.nstate:
            raise UserError(
                f"{self.name}: a scene's physics state has {len(state)} numbers, not "
                f"{self.nstate} (a scene of another model?)"
            )
        mujoco.mj_setState(u.model, u.data, state, STATE_BITS)
        for k, slot in enumerate(self.distractors):
            o = scene.obj(slot)
            joint = u.model.joint(f"{slot}:joint")
            qa, va = joint.qposadr[0], joint.dofadr[0]
            parked = np.abs(u.data.qpos[qa : qa + 3] - M.park_pos(k)).max() < 0.01
            M.take_part(u.model, self._looks[slot], o.present)
            if not o.present:
                u.data.qpos[qa : qa + 7] = [*M.park_pos(k), 1.0, 0.0, 0.0, 0.0]
                u.data.qvel[va : va + 6] = 0.0
            elif parked:  # brought into the workspace: it starts where the scene says
                u.data.qpos[qa : qa + 7] = [*o.pos[:3], 1.0, 0.0, 0.0, 0.0]
                u.data.qvel[va : va + 6] = 0.0
        self.set_goal(env, self.goal_of(scene))
        for slot, looks in self._looks.items():
            M.paint(u.model, looks, scene.obj(slot).value(COLOUR))
        mujoco.mj_forward(u.model, u.data)
        return env

    def scene_of(self, env, t: int, like: Scene, success: bool | None = None) -> Scene:
        """The environment's current state as a scene: `like`'s looks, the places as they are;
        `success` as its last step said (None: judged on the state as it is)."""
        u = env.unwrapped
        objects = []
        for spec in self.all_slots():
            o = like.obj(spec.name)
            pos = o.pos
            if spec.moves and (o.present or spec.name not in self.distractors):
                pos = tuple(round(float(v), 9) for v in u.data.body(spec.body).xpos)
            objects.append(Obj(o.slot, o.present, o.values, pos))
        goal = tuple(float(v) for v in self.goal(env))
        if success is None:
            success = self.env_success(env)
        state = map(float, self._state(env))
        return Scene(self.name, tuple(objects), (float(t), float(success), *goal, *state))

    # -- appearance ---------------------------------------------------------------------------
    def before_render(self, env) -> None:
        """What the environment does to its model before it draws (e.g. Fetch's target marker
        moved to the goal); nothing by default."""

    def _renderer(self):
        """One mujoco.Renderer on the environment's model and a free camera set as the
        environment's default_camera_config sets its own: the same pixels as its render()."""
        if self._camera is None:
            import mujoco

            from sim.mjworld.gl import release_egl

            model = self._open().unwrapped.model
            renderer = mujoco.Renderer(model, self.size_px, self.size_px)
            release_egl()  # the constructor left the context current in this thread
            atexit.register(renderer.close)  # before EGL itself is let go at exit
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            for key, value in self.camera.items():
                if key == "lookat":
                    cam.lookat[:] = value
                else:
                    setattr(cam, key, value)
            self._camera = (renderer, cam)
        return self._camera

    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3): the environment's camera on each scene."""
        from sim.mjworld.gl import current

        out = np.empty((len(scenes), *self.obs_shape), np.uint8)
        with self._lock:
            renderer, cam = self._renderer()
            with current(renderer):
                for b, scene in enumerate(scenes):
                    env = self.restore(scene)
                    self.before_render(env)
                    renderer.update_scene(env.unwrapped.data, camera=cam)
                    renderer.render(out=out[b])
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
