"""robosuite's manipulation environments as worlds, through the generic MuJoCo layer
(sim.mjworld): the environment's own model, controller, step, camera and success.

Name: `robosuite:<Env>[:robot=<Robot>][:camera=<camera>]`, e.g. `robosuite:Lift` or
`robosuite:Stack:robot=Panda:camera=frontview` (defaults: robot Panda, camera agentview). Env:
Lift or Stack (TASKS); robot: one of ROBOTS (the scripted demonstrators are measured on Panda;
the lift also on IIWA, Kinova3 and UR5e); camera: one of the model's cameras.

Concepts  each object of the task (Lift: cube; Stack: cubeA, cubeB; the environment's
          mujoco_objects, by their root bodies) and the table: colour over
          sim.mjworld.model.PALETTE (each as built: a textured material); distractor0 (kind
          "distractor", optional): a spare block, colour
Actions   the OSC controller's own 7 (robosuite 1.5's BASIC composite controller, OSC_POSE,
          delta input): end effector (dx, dy, dz) (1 = 0.05 m), rotation (dax, day, daz)
          (1 = 0.5 rad) and gripper (+1 closes), each in [-1, 1]; one step is one control step
          at 20 Hz (25 physics steps)
Shifts    object_ti (the picked cube or the table recoloured), object_tr (Stack: cube B
          recoloured, R' names its colour; Lift has no target and no object_tr),
          distractor_ti (a block added clear of the way), distractor_tr (a block added, R'
          says leave it where it is), other (the picked cube starts beside the table's middle,
          UNSEEN_Y_M, where the environment's own placement never puts it)
Success   the environment's own `_check_success()` after the last step (Lift: the cube 4 cm
          over the table; Stack: cube A on cube B, lifted, not held)

A scene holds, beside MuJoCo's integration state, what robosuite's step reads from outside it:
the gripper's commanded opening (`current_action`, which its gripper model accumulates across
steps) and the joint positions the OSC controller pulls its null space towards (`initial_joint`,
the robot's noisy start at its reset): restoring these and calling the environment's step gives
its own rollout. The environment is made with
hard_reset=False (one model for the world's life), ignore_done=True (the world counts steps)
and no camera observations: frames are drawn from the same camera with the same geom groups
(1 and 2: robosuite does not draw collision geoms) by the world's renderer, and equal the
environment's own camera observation of the same state turned right side up (robosuite's
default image convention is OpenGL's, bottom row first). The observation robosuite's step
returns is drawn before the body poses catch up with its last physics substep (2 ms behind the
state it returns); the world's frame is of the state itself.
"""

from __future__ import annotations

import contextlib
import io
import logging
import sys
from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np

from sim.core import Cloning, Scene, UserError
from sim.mjworld import tasks as MT
from sim.mjworld.world import MujocoWorld, SlotSpec
from sim.robosuite import expert as X

TASKS = {
    "Lift": ("lift the cube", 50),
    "Stack": ("put the red cube on the green cube", 100),
}
# single-arm robots robosuite builds without extra packages, on which the scripted lift
# succeeds (3 of 3 training tasks each); not offered: Sawyer (robosuite 1.5.1 cannot build its
# model on MuJoCo 3.3.7: "mesh volume is too small: robot0_head_1") and Jaco (its three-finger
# gripper: the scripted lift fails 3 of 3)
ROBOTS = ("Panda", "IIWA", "Kinova3", "UR5e")
DEFAULT_ROBOT, DEFAULT_CAMERA = "Panda", "agentview"
SIZE_PX = 84
CONTROL_HZ = 20
TABLE_X_M, TABLE_Y_M = (-0.15, 0.15), (-0.2, 0.2)  # where a distractor may stand
UNSEEN_Y_M = (0.14, 0.2)  # `other`: the picked cube's y (the env's own placement: |y| <= 0.08)
ARM = "right"  # a single-arm robot's arm, as robosuite names it
BUILD_SEED = 0  # numpy's global generator is seeded with it while robosuite builds the model


def parse(rest: str) -> tuple[str, str, str]:
    """(env, robot, camera) of "<Env>[:robot=<Robot>][:camera=<camera>]", checked (the
    camera against the model once it is built)."""
    env_name, *options = rest.split(":")
    robot, camera = DEFAULT_ROBOT, DEFAULT_CAMERA
    for opt in options:
        key, _, value = opt.partition("=")
        if key == "robot" and value in ROBOTS:
            robot = value
        elif key == "camera" and value:
            camera = value
        else:
            raise UserError(
                f"robosuite:{rest}: unknown option {opt!r}; accepted: "
                f"robot={'|'.join(ROBOTS)}, camera=<a camera of the model>"
            )
    if env_name not in TASKS:
        raise UserError(
            f"robosuite:{env_name}: not a robosuite task offered here; accepted: {', '.join(TASKS)}"
        )
    return env_name, robot, camera


def robosuite_world(rest: str) -> RobosuiteWorld:
    """The registry's factory for names "robosuite:<Env>[:robot=...][:camera=...]"."""
    env_name, robot, camera = parse(rest)
    return RobosuiteWorld(env_name, robot=robot, camera=camera)


def import_robosuite():
    """robosuite, imported with its import-time notes (no private macro file, no
    robosuite_models) kept off the terminal; its log shows warnings after that, not its INFO
    lines."""
    buffer = io.StringIO()
    try:
        with contextlib.redirect_stderr(buffer):
            import robosuite
    except ImportError:
        raise UserError(
            "the robosuite worlds need robosuite: pip install -e '.[robotics]'"
        ) from None
    for handler in logging.getLogger("robosuite_logs").handlers:
        if isinstance(handler, logging.StreamHandler) and handler.stream is buffer:
            handler.setStream(sys.stderr)
            handler.setLevel(logging.WARNING)
    return robosuite


def _arm(env):
    """The arm's part controller (OSC)."""
    return env.robots[0].composite_controller.part_controllers[ARM]


@contextlib.contextmanager
def seeded(seed: int) -> Iterator[None]:
    """numpy's global generator, which robosuite draws from (its objects' sizes when it builds
    a model, its robot's noise and its objects' places when it resets), seeded for a block and
    put back as it was after."""
    outside = np.random.get_state()
    try:
        np.random.seed(int(np.random.SeedSequence([seed]).generate_state(1)[0]))
        yield
    finally:
        np.random.set_state(outside)


class RobosuiteWorld(MujocoWorld):
    """One robosuite task; see the module docstring."""

    epsilon = 0.35  # per step, L1 over the 7 action components
    cloning = Cloning(demonstrations=200, steps=6000, noise=0.15)
    action_names = ("eef dx", "eef dy", "eef dz", "eef dax", "eef day", "eef daz", "gripper")
    drawn_groups = (1, 2)  # robosuite's cameras draw visual geoms, not collision ones
    demo_input = "effector"

    def __init__(self, env_name: str, *, robot: str = DEFAULT_ROBOT, camera: str = DEFAULT_CAMERA):
        self.env_name, self.robot, self.camera = env_name, robot, camera
        self.instruction, horizon = TASKS[env_name]
        stacking = env_name == "Stack"
        suffix = (f":robot={robot}" if robot != DEFAULT_ROBOT else "") + (
            f":camera={camera}" if camera != DEFAULT_CAMERA else ""
        )
        self._grip_start = np.zeros(3)
        self.workspace = MT.Workspace(
            TABLE_X_M,
            TABLE_Y_M,
            0.0,  # set from the model once it is built
            recoloured=("cubeA" if stacking else "cube", "table"),
            target=("cubeB", "the green cube", "cube") if stacking else None,
        )
        super().__init__(
            f"robosuite:{env_name}{suffix}", horizon=horizon, action_dim=7, size_px=SIZE_PX
        )

    # -- hooks ------------------------------------------------------------------------------
    def open_env(self, add_bodies: Callable):
        robosuite = import_robosuite()
        import mujoco
        from robosuite.controllers import load_composite_controller_config
        from robosuite.utils.binding_utils import MjSim

        base = robosuite.environments.base.REGISTERED_ENVS[self.env_name]

        class WithBodies(base):
            def _initialize_sim(self, xml_string=None):  # the env's own, bodies added first
                xml = xml_string if xml_string else self.model.get_xml()
                for processor in self._xml_processors:
                    xml = processor(xml)
                spec = mujoco.MjSpec.from_string(xml)
                add_bodies(spec)
                self.sim = MjSim(spec.compile())
                self.sim.forward()
                self.initialize_time(self.control_freq)

        config = load_composite_controller_config(controller="BASIC", robot=self.robot)
        # the arm's part only: robosuite warns on every reset about the parts (left arm,
        # torso, head, base, legs) a single-arm robot does not have
        config["body_parts"] = {ARM: config["body_parts"][ARM]}
        with seeded(BUILD_SEED):  # the same model (e.g. Lift's cube size) in every process
            env = WithBodies(
                robots=self.robot,
                controller_configs=config,
                has_renderer=False,
                has_offscreen_renderer=False,
                use_camera_obs=False,
                hard_reset=False,
                ignore_done=True,
                control_freq=CONTROL_HZ,
            )
        model, _ = self.physics(env)
        cameras = [model.camera(i).name for i in range(model.ncam)]
        if self.camera not in cameras:
            raise UserError(
                f"{self.name}: no camera {self.camera!r} in the model; accepted: "
                f"{', '.join(cameras)}"
            )
        self.slot_specs = (
            *(SlotSpec(o.name, body=o.root_body, moves=True) for o in env.model.mujoco_objects),
            SlotSpec("table", body="table"),
        )
        self.effector = env.robots[0].gripper[ARM].root_body  # the gripper, in the 3D view
        top = float(env.model.mujoco_arena.table_offset[2])
        self.workspace = replace(self.workspace, top_m=top)
        env.reset()
        self._grip_start = self.grip_pos(env)
        return env

    def physics(self, env) -> tuple:
        return env.sim.model._model, env.sim.data._data

    def env_state(self, env) -> np.ndarray:
        """float (gripper actuators + arm joints): the gripper's commanded opening (robosuite
        accumulates it across steps; a reset leaves it one zero, which stands for all) and the
        joint positions the arm's controller holds its null space to (its reset's)."""
        gripper = env.robots[0].gripper[ARM]
        opening = np.broadcast_to(gripper.current_action, (len(gripper.actuators),))
        return np.concatenate([opening, _arm(env).initial_joint]).astype(float)

    def set_env_state(self, env, state: np.ndarray) -> None:
        gripper = env.robots[0].gripper[ARM]
        n = len(gripper.actuators)
        gripper.current_action = np.array(state[:n], float)
        _arm(env).initial_joint = np.array(state[n:], float)
        # the controllers read the restored state at the next step, as robosuite's own step
        # finds them (each control step ends with them asking to be updated), not what they
        # cached from a state before
        for controller in env.robots[0].composite_controller.part_controllers.values():
            controller.new_update = True

    def env_step(self, env, action: np.ndarray) -> bool:
        env.step(np.asarray(action, np.float64))
        return bool(env._check_success())

    def env_success(self, env) -> bool:
        return bool(env._check_success())

    def grip_pos(self, env) -> np.ndarray:
        _, data = self.physics(env)
        return np.array(data.site_xpos[env.robots[0].eef_site_id[ARM]])

    def effector_action(self, grip: np.ndarray, to: np.ndarray, close: bool) -> np.ndarray:
        return X.move(to, grip, 1.0 if close else -1.0)

    # -- the expert ---------------------------------------------------------------------------
    def expert_action(self, task, scene) -> np.ndarray:
        with self._lock:
            env = self.restore(scene)
            _, data = self.physics(env)
            eef = self.grip_pos(env)
            objects = env.model.mujoco_objects
            objs = [np.array(data.body(o.root_body).xpos) for o in objects]
            held = bool(env._check_grasp(env.robots[0].gripper[ARM], objects[0]))
            top = self.workspace.top_m
            if self.env_name == "Lift":
                return X.lift(eef, objs, held, top)
            rest_dz = float(objects[0].top_offset[2] - objects[1].bottom_offset[2])
            return X.stack(eef, objs, held, top, rest_dz)

    # -- tasks ---------------------------------------------------------------------------------
    def reset_scene(self, seed: int, *, unseen: bool = False) -> Scene:
        """The environment's own reset (its robot noise and object placement), `seeded`;
        `unseen`: the picked cube moved to y in UNSEEN_Y_M."""
        import mujoco

        rng = np.random.default_rng([seed, 5])
        with self._lock:
            env = self._open()
            with seeded(seed):
                env.reset()
            model, data = self.physics(env)
            if unseen:
                joint = env.model.mujoco_objects[0].joints[0]
                data.joint(joint).qpos[1] = rng.uniform(*UNSEEN_Y_M)
                mujoco.mj_forward(model, data)
            table = tuple(float(v) for v in data.body("table").xpos)
            return MT.initial_scene(self, env, {"table": table})

    def keep_clear(self, scene: Scene) -> list[np.ndarray]:
        """The objects' (x, y) and the gripper's start."""
        pts = [np.asarray(scene.obj(s.name).pos[:2]) for s in self.slot_specs if s.moves]
        return [*pts, self._grip_start[:2]]

    def way(self, scene: Scene):
        """Stack: from cube A to cube B; Lift carries nothing across the table."""
        if self.env_name != "Stack":
            return None
        return np.asarray(scene.obj("cubeA").pos[:2]), np.asarray(scene.obj("cubeB").pos[:2])
