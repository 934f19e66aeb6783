"""gymnasium-robotics' Fetch tasks as worlds: `fetch:<EnvId>` for FetchPickAndPlace-v4,
FetchPush-v4, FetchSlide-v4 and FetchReach-v4, through the generic MuJoCo layer
(sim.mjworld): the environment's own model, controller, step, camera and success.

Concepts  object (the block, the puck in Slide; not in Reach), target (the goal marker), table:
          colour over sim.mjworld.model.PALETTE (the model's own colours are its "dark grey",
          "red", "light grey"); distractor0 (kind "distractor", optional): a spare block, colour
Actions   Fetch's own 4: gripper (dx, dy, dz) and fingers, each in [-1, 1]; 50 steps
Shifts    object_ti (the object or the table recoloured), object_tr (the target recoloured, R'
          names its colour), distractor_ti (a block added clear of the way), distractor_tr (a
          block added, R' says leave it where it is), other (the object starts where training
          never put it: further along +x, FetchTask.unseen_min_dx_m)
Success   the environment's own `_is_success` (the object, or the gripper in Reach, within
          0.05 m of the goal) at the last step

Frames are the environment's own `render()` at 84 x 84 from a camera over the table (CAMERA),
passed to the environment as its default_camera_config; PickAndPlace's have a second 84 x 84
view to the right of it (FRONT, across the table, low): from the first alone a target in the
air could stand anywhere along the camera's ray.

Demonstrators: sim.fetch.expert (pick and place, push, reach: closed loop on the state) and
sim.fetch.slide (Slide: strikes chosen by stepping the world itself; it brings the puck within
the 0.05 m on 17 of the 20 training tasks of seeds 0-19, in about 5-10 s a demonstration on 2
cores).
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import gymnasium
import numpy as np

from sim.core import Adapting, Cloning, UserError
from sim.fetch import expert as X
from sim.fetch import tasks as TK
from sim.mjworld.world import MujocoWorld, SlotSpec

CLONING = Cloning(demonstrations=200, steps=6000, noise=0.15)
"""Closed loop over 50 steps: many demonstrations, with noise on what they execute."""


@dataclass(frozen=True)
class FetchTask:
    """What a Fetch task's world needs beside the environment."""

    instruction: str
    expert: Callable | None
    """(grip, obj, goal, finger width) -> action; None: sim.fetch.slide's striking one."""
    train_max_dx_m: float = 0.05
    """Training resets put the object at most this far beyond the gripper's start along x."""
    unseen_min_dx_m: float = 0.10
    """`other` resets put it at least this far beyond it (where training never does)."""
    clear_path: bool = False
    """An added distractor also keeps clear of the object's way to the goal (a sliding puck
    cannot be steered round it)."""
    cloning: Cloning = CLONING
    """How its base policy is cloned."""
    extra_views: tuple[dict, ...] = ()
    """Cameras drawn beside CAMERA in every frame (MujocoWorld.extra_views)."""
    adapting: Adapting = field(default_factory=Adapting)
    """How `dfa run` finetunes its policies (by default the paper's settings)."""


SIZE_PX = 84
CAMERA = {  # from the side, over the table: the arm hides little of the workspace
    "distance": 0.9,
    "azimuth": 90.0,
    "elevation": -50.0,
    "lookat": np.array([1.32, 0.75, 0.45]),
}
FRONT = {  # facing the robot across the table, low: how high the gripper and target are
    **CAMERA,
    "azimuth": 180.0,
    "elevation": -25.0,
}

TASKS = {
    "FetchPickAndPlace-v4": FetchTask(
        "put the block on the target",
        X.pick_and_place,
        # keypoints (side view only: 5/30 held-out tasks, the flatten head 1/30), then DAgger
        # (the clone's own states labelled by the demonstrator): 20/30 with both views at 2000
        # steps a fit; frames shifted by up to 4 px and 4000 steps a fit: 26/30 (README)
        cloning=replace(
            CLONING,
            steps=4000,
            dagger_rounds=2,
            head="spatial_softmax",
            lr_schedule="cosine",
            shift_px=4,
        ),
        extra_views=(FRONT,),
        # the paper's finetuning moves no held-out colour (README): many variants in many
        # colours, the replayed training data painted beyond the named colours, and DAgger
        # rounds for the table, which fills most of the frame (about 70 min on 2 cores)
        adapting=Adapting(
            budget=100, steps=3000, looks="spread", replay_looks="painted", dagger_rounds=2
        ),
    ),
    "FetchPush-v4": FetchTask("push the block onto the target", X.push),
    # the puck starts within 0.1 m of the gripper's start along x: the split is nearer it
    "FetchSlide-v4": FetchTask("slide the puck onto the target", None, 0.0, 0.05, clear_path=True),
    "FetchReach-v4": FetchTask("move the gripper to the target", X.reach),
}


def parse(rest: str) -> str:
    """The env id of "fetch:<EnvId>", checked."""
    if rest not in TASKS:
        raise UserError(f"fetch:{rest}: not a Fetch task; accepted: {', '.join(TASKS)}")
    return rest


def fetch_world(rest: str) -> FetchWorld:
    """The registry's factory for names "fetch:<EnvId>"."""
    return FetchWorld(parse(rest))


def register_robotics() -> None:
    """gymnasium-robotics' environments in gymnasium's registry (its import prints a note about
    other environments; that note is not ours to print)."""
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            import gymnasium_robotics
    except ImportError:
        raise UserError(
            "the Fetch worlds need gymnasium-robotics: pip install -e '.[robotics]'"
        ) from None
    gymnasium.register_envs(gymnasium_robotics)


class FetchWorld(MujocoWorld):
    """One Fetch task; see the module docstring."""

    epsilon = 0.25  # per step, L1 over the 4 action components
    action_names = ("gripper dx", "gripper dy", "gripper dz", "fingers")
    effector = "robot0:gripper_link"  # the gripper and its two fingers, in the 3D view
    demo_input = "effector"

    def __init__(self, env_id: str) -> None:
        self.env_id, self.task = env_id, TASKS[env_id]
        self.cloning, self.adapting = self.task.cloning, self.task.adapting
        self.instruction = self.task.instruction
        has_object = env_id != "FetchReach-v4"
        self.slot_specs = (
            *((SlotSpec("object", body="object0", moves=True),) if has_object else ()),
            SlotSpec("target", site="target0"),
            SlotSpec("table", body="table0"),
        )
        self.camera, self.extra_views = CAMERA, self.task.extra_views
        self.workspace = TK.workspace(has_object)
        super().__init__(f"fetch:{env_id}", horizon=50, action_dim=4, size_px=SIZE_PX)

    # -- hooks ------------------------------------------------------------------------------
    def open_env(self, add_bodies: Callable):
        register_robotics()
        spec = gymnasium.registry[self.env_id]
        module, _, name = spec.entry_point.partition(":")
        import importlib

        base = getattr(importlib.import_module(module), name)

        class WithBodies(base):
            def _initialize_simulation(self):  # the env's own, with the bodies added first
                import mujoco

                model_spec = mujoco.MjSpec.from_file(self.fullpath)
                add_bodies(model_spec)
                self.model = model_spec.compile()
                self.data = mujoco.MjData(self.model)
                self._model_names = self._utils.MujocoModelNames(self.model)
                self.model.vis.global_.offwidth = self.width
                self.model.vis.global_.offheight = self.height
                self._env_setup(initial_qpos=self.initial_qpos)
                self.initial_time = self.data.time
                self.initial_qpos = np.copy(self.data.qpos)
                self.initial_qvel = np.copy(self.data.qvel)

        env = WithBodies(
            render_mode="rgb_array",
            width=self.size_px,
            height=self.size_px,
            default_camera_config=self.camera,
            **spec.kwargs,
        )
        env.reset(seed=0)
        return env

    def before_render(self, env) -> None:
        env._render_callback()  # the target marker at the goal, as Fetch's render() puts it

    def env_step(self, env, action: np.ndarray) -> bool:
        _, _, _, _, info = env.step(np.asarray(action, np.float32))
        return bool(info["is_success"])

    def env_success(self, env) -> bool:
        obs = env._get_obs()
        return bool(env._is_success(obs["achieved_goal"], env.goal))

    def env_state(self, env) -> np.ndarray:
        """float (3,): the environment's goal (x, y, z)."""
        return np.array(env.goal, float)

    def set_env_state(self, env, state: np.ndarray) -> None:
        env.goal = np.array(state, float)

    def goal_of(self, scene) -> np.ndarray:
        """float (3,): the goal in `scene`."""
        return self.env_state_of(scene)

    # -- the expert ---------------------------------------------------------------------------
    def expert_action(self, task, scene) -> np.ndarray:
        if self.task.expert is None:
            from sim.fetch import slide

            return slide.act(self, scene)
        with self._lock:
            env = self.restore(scene)
            d, m = env.data, env.model
            grip = np.array(d.site("robot0:grip").xpos)
            obj = np.array(d.site("object0").xpos) if self.env_id != "FetchReach-v4" else None
            width = sum(
                float(d.qpos[m.joint(f"robot0:{s}_gripper_finger_joint").qposadr[0]]) for s in "lr"
            )
            goal = self.goal_of(scene)
        return self.task.expert(grip, obj, goal, width)

    # -- tasks (sim.fetch.tasks) ---------------------------------------------------------
    def reset_scene(self, seed: int, *, unseen: bool = False):
        return TK.reset_scene(self, seed, unseen=unseen)

    def keep_clear(self, scene) -> list[np.ndarray]:
        return TK.keep_clear(self, scene)

    def way(self, scene):
        return TK.way(self, scene)

    def grip_pos(self, env) -> np.ndarray:
        return np.array(env.data.site("robot0:grip").xpos)

    def effector_action(self, grip: np.ndarray, to: np.ndarray, close: bool) -> np.ndarray:
        return X.move(to, grip, -1.0 if close else 1.0)
