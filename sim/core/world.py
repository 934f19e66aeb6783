"""The World interface every environment implements, and rollouts written once against it."""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from sim.core.concepts import ConceptSpace
from sim.core.edit import Edit, apply, apply_many
from sim.core.effector import Waypoint
from sim.core.errors import UserError
from sim.core.parameters import SceneParameter
from sim.core.recipes import Adapting, Cloning
from sim.core.scene import Scene
from sim.core.task import SHIFTS, Reward, Task
from sim.core.trajectory import Trajectory
from sim.core.view3d import View3D

# obs uint8 (B, H, W, 3) -> actions float32 (B, A) or int64 (B,)
ActBatch = Callable[[np.ndarray], np.ndarray]
DemoInput = Literal["waypoints", "keys", "pick_place", "effector", "file"]
Criterion = Literal["follows", "succeeds"]
RGB = tuple[float, float, float]


@dataclass(frozen=True)
class Paints:
    """A look concept whose values are colours, which the renderer also draws in any colour
    (`World.render_painted`): beyond the concept's named values, a continuum of them."""

    concept: str
    """The concept ("colour")."""
    rgb: dict[str, RGB]
    """Each named value's red, green and blue in [0, 1] (values not here have none)."""


@dataclass(frozen=True)
class Key:
    """A discrete action the page offers as a button and a hotkey (demo_input "keys")."""

    label: str
    hotkey: str
    """A viser HotkeyKey, e.g. "arrowleft" or "P"."""
    action: int


class World(abc.ABC):
    """One world: what diagnosing a policy in it needs, and the capabilities tools read.

    A world must give its concept space, a renderer (Phi^-1), dynamics and R' as a success
    predicate; the editor f comes from the concept space. What the paper's benchmark adds (a
    training distribution, planted shifts, fresh tasks to score on, a scripted expert) is
    `Benchmark`'s: a plain World is diagnosed from a user's demonstration.

    Attributes set by each world:
        name: registry name ("nav2d", "doorkey", "tabletop", "minigrid:<EnvId>", ...).
        space: the concept space.
        horizon: steps per episode (T).
        obs_shape: (H, W, 3) of a rendered observation.
        discrete: True when actions are integers in [0, action_dim).
        action_dim: continuous action size, or the number of discrete actions.
        epsilon: the search's per-step L1 bound on action distance (continuous worlds).

    Capabilities, each with a default (tools read these, never the world's name):
        lossless_frames: record frames losslessly (small synthetic images) instead of JPEG.
        search_first_only: a size >= 2 search stops at its first valid edit (large spaces).
        search_max_candidates: the search stops after this many candidates (None: never).
        demo_input: how the page takes a demonstration: "waypoints" (clicks on the image; an
            action moves the agent, scene.agent[:2], by (dx, dy)), "keys" (`keys`, one step
            each), "pick_place" (a click to pick, one to place: action (pick x, y, place x,
            y)), "effector" (waypoints of a robot's end effector clicked on its frames:
            `effector_waypoint` and `follow`), or "file" (a saved trajectory only).
        keys, idle_action: for "keys", the buttons and hotkeys, and the action that fills the
            steps left after the user stops.
        image_extent: (x_left, x_right, y_bottom, y_top) of the rendered frame in the world's
            coordinates, for the click inputs.
        view3d: a 3D scene (sim.core.view3d.View3D), or None.
        action_names: a name per continuous action dimension for plots (default "action k");
            for a discrete world, a name per action (DoorKey: "turn left", ..., "toggle").
        shifts: the shift kinds `test_task` makes (Benchmark worlds).
        cloning: how its base policy is cloned (Cloning: demonstrations, steps, action noise).
        adapting: how `dfa run` finetunes in it where the paper's settings do not lift success
            (Adapting: budget, steps, looks, DAgger rounds; by default the paper's).
        description: what the agent is and what it should do, in a sentence or two for a
            person who has never seen the world (the study's familiarisation); empty: tools
            say a training task's instruction instead.
        intent(task): what the user wants in plain words, naming nothing R' leaves open (the
            study's questions; default: the reward's instruction).
        scene_parameters: continuous scene parameters the concept space does not enumerate
            (sim.core.parameters: an object's x and y), each with its range; set with
            `with_parameters`, read back with `parameters_of` (none by default).
        appearance_concepts: concepts that change how a scene looks, never how it moves:
            scenes that differ only in them, stepped with the same action, give next scenes
            that differ only in them, each object keeping its values (the sweep's expert check
            steps one of each such group; none by default).
        simulated: a rollout's steps are a physics simulation (MuJoCo), so what they cost is
            the simulator's: `dfa bench` holds the sweep to the larger of its forward-pass
            and physics bounds (False by default: the forward-pass bound).
        counterfactual: what makes an edited scene a counterfactual (search.lockstep).
            "follows" (the paper's, by default): the policy's action at every step is the
            demonstration's (within `epsilon`), each step from the state the policy's own
            actions reached. "succeeds", for closed-loop control where a policy that does the
            task still drifts a little from any one demonstration and its actions then differ
            from those the demonstration took in other states: the policy, rolled out from
            the edited scene to the horizon, does the task (R' holds). The demonstration then
            shows the task can be done and gives the action distances the search ranks by.
        paints: a colour concept the renderer draws in any colour (`Paints`;
            `render_painted`), or None (by default: only the named values).
    """

    name: str
    space: ConceptSpace
    horizon: int
    obs_shape: tuple[int, int, int]
    discrete: bool
    action_dim: int
    epsilon: float = 0.0
    lossless_frames: bool = False
    search_first_only: bool = False
    search_max_candidates: int | None = None
    demo_input: DemoInput = "file"
    keys: tuple[Key, ...] = ()
    idle_action: int = 0
    image_extent: tuple[float, float, float, float] | None = None
    view3d: View3D | None = None
    action_names: tuple[str, ...] = ()
    shifts: tuple[str, ...] = ()
    cloning: Cloning = Cloning()
    adapting: Adapting = Adapting()
    description: str = ""
    benchmark: bool = False
    """True for a Benchmark: training tasks, test tasks, fresh tasks and an expert."""
    scene_parameters: tuple[SceneParameter, ...] = ()
    appearance_concepts: frozenset[str] = frozenset()
    simulated: bool = False
    counterfactual: Criterion = "follows"
    paints: Paints | None = None

    # -- appearance ---------------------------------------------------------------------------
    @abc.abstractmethod
    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3); deterministic: the same scene gives the same pixels."""

    def render_painted(
        self, scenes: Sequence[Scene], paints: Sequence[dict[str, RGB]]
    ) -> np.ndarray:
        """uint8 (B, H, W, 3): each scene with the slots in paints[b] in those colours (the
        `paints` concept's), the rest as render_batch draws it. Worlds with `paints` only."""
        raise UserError(f"{self.name} draws only its named colours")

    def render(self, scene: Scene) -> np.ndarray:
        """uint8 (H, W, 3)."""
        return self.render_batch([scene])[0]

    def apply(self, scene: Scene, edit: Edit) -> Scene:
        """The editor f on this world's concept space."""
        return apply(self.space, scene, edit)

    def apply_batch(self, scene: Scene, edits: Sequence[Edit]) -> list[Scene]:
        """[self.apply(scene, e) for e in edits], each slot's changes made once per batch."""
        return apply_many(self.space, scene, edits)

    def effector_waypoint(
        self, scene: Scene, u: float, v: float, last: Waypoint | None
    ) -> Waypoint | None:
        """demo_input "effector": the waypoint a click at (u, v) on a frame of `scene` makes
        (u to the right, v down, each in [0, 1] over the whole frame); `last`: the waypoint
        clicked before it, which a click in a view that sets heights moves. None: the click
        met nothing it could mean."""
        raise UserError(f"{self.name} takes no clicked waypoints")

    def follow(self, task: Task, waypoints: Sequence[Waypoint]) -> Trajectory:
        """demo_input "effector": the rollout of the end effector led through `waypoints`
        from the task's scene."""
        raise UserError(f"{self.name} takes no clicked waypoints")

    # -- dynamics -----------------------------------------------------------------------------
    @abc.abstractmethod
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        """Advance every scene by its action: actions (B, A) float32 or (B,) int64.

        A scene for which `done` holds is returned unchanged (the episode has ended).
        """

    def done(self, scene: Scene) -> bool:
        """True once nothing more can happen (an episode may end before the horizon)."""
        return False

    def success(self, task: Task, scenes: Sequence[Scene]) -> bool:
        """R' judged on the states of one rollout (scenes[0] is the initial scene); never True
        for a rollout with a non-finite number in any of its states."""
        return all(s.is_finite() for s in scenes) and self.meets_reward(task, scenes)

    @abc.abstractmethod
    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        """R' on the finite states of one rollout (what `success` asks of each world)."""

    # -- scenes, tasks and variants ----------------------------------------------------------
    @abc.abstractmethod
    def sample_scene(self, seed: int) -> Scene:
        """A scene of this world (what its gymnasium env resets to; the contract tests use it)."""

    def task_for(self, scene: Scene) -> Task:
        """A task for a scene a user brings (e.g. their demonstration's first scene): R' is
        the world's success predicate, and names no concept relevant."""
        return Task(
            self.name,
            scene,
            Reward("do what the world's success predicate asks", frozenset()),
            "user",
            0,
        )

    def intent(self, task: Task) -> str:
        """What the user wants in `task`, in plain words that name only what R' holds fixed:
        never a concept it leaves open ("whatever its shape", "wherever it is"), nor the look
        of what it says to keep clear of, nor the value of a changed look it requires (the
        thing "as it looks here"). The study asks this, so that its wording does not say what
        changed. By default the reward's instruction, which may name all of them."""
        return task.reward.instruction

    def notes(self, task: Task) -> tuple[str, ...]:
        """What a report says about a task beside its instruction, a line each (() by
        default; MiniGrid: that the mission names a target the frames do not show)."""
        return ()

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        """Positions for adding `slot` to the demonstration's scenes without blocking its path
        ([] by default: a variant can then remove the object, not add it)."""
        return []

    def in_the_way(self, task: Task, slot: str) -> list[tuple[float, ...]]:
        """Positions where `slot`, added to the task's scene in any look it can take, is in
        the way of what the task asks while R' stays within reach: where the sweep tries an
        added object besides the place the scene keeps for it ([] by default: only there)."""
        return []

    def with_parameters(self, scene: Scene, values: Sequence[float]) -> Scene:
        """`scene` with its `scene_parameters` set to `values` (one float each, in the world's
        coordinates); sim.core.parameters.InvalidScene where they give no valid scene (out of
        range, objects overlapping). Only for a world that declares scene parameters."""
        raise UserError(f"{self.name} has no continuous scene parameters")

    def parameters_of(self, scene: Scene) -> tuple[float, ...]:
        """The values of `scene_parameters` in `scene`, in their order."""
        raise UserError(f"{self.name} has no continuous scene parameters")

    def make_env(self):
        """This world as a gymnasium environment (the generic sim.core.env.SceneEnv unless the
        world has its own)."""
        from sim.core.env import SceneEnv

        return SceneEnv(self)

    # -- rollouts, written once ---------------------------------------------------------------
    def rollout_batch(
        self, tasks: Sequence[Task], act: ActBatch, *, scenes: Sequence[Scene] | None = None
    ) -> list[Trajectory]:
        """Roll `act` out on many tasks in lockstep: one batched render and act per step.

        scenes: initial scenes to start from instead of the tasks' own (e.g. edited ones).
        Once every episode has ended, the steps left repeat the last frame and action (an
        ended scene does not change, whatever the action).
        """
        cur = list(scenes if scenes is not None else (t.scene for t in tasks))
        history = [[s] for s in cur]
        frames = [self.render_batch(cur)]  # each (B, H, W, 3)
        actions: list[np.ndarray] = []  # each (B,) or (B, A)
        for t in range(self.horizon):
            if actions and all(self.done(s) for s in cur):
                frames.append(frames[-1])
                actions.append(actions[-1])
                for h in history:
                    h.append(h[-1])
                continue
            a = np.asarray(act(frames[-1]))  # (B, A) | (B,)
            if not self.discrete and not np.isfinite(a).all():
                raise UserError(
                    f"the policy's actions at step {t} are not finite numbers: a policy with "
                    "non-finite outputs cannot be rolled out or scored"
                )
            cur = self.step_batch(cur, a)
            for h, s in zip(history, cur, strict=True):
                h.append(s)
            frames.append(self.render_batch(cur))
            actions.append(a)
        obs = np.stack(frames, axis=1)  # (B, T+1, H, W, 3)
        acts = np.stack(actions, axis=1)  # (B, T, A) | (B, T)
        return [
            Trajectory(tuple(h), obs[i], acts[i], self.success(t, h))
            for i, (t, h) in enumerate(zip(tasks, history, strict=True))
        ]

    def rollout(self, task: Task, act: ActBatch, *, scene: Scene | None = None) -> Trajectory:
        return self.rollout_batch([task], act, scenes=None if scene is None else [scene])[0]

    def replay(self, task: Task, actions: np.ndarray) -> Trajectory:
        """The trajectory `actions` make from the task's scene: (T, A) float32 or (T,) int64,
        stepped through this world's dynamics, rendered, and judged by R'."""
        scenes = [task.scene]
        for a in actions:
            scenes.append(self.step_batch([scenes[-1]], np.asarray(a)[None])[0])
        obs = self.render_batch(scenes)  # (T+1, H, W, 3)
        return Trajectory(tuple(scenes), obs, np.asarray(actions), self.success(task, scenes))


class Benchmark(World):
    """A World with the paper's benchmark generator: a training distribution the base policy
    is cloned on, the planted shifts (`shifts`), fresh tasks to score on, a scripted expert."""

    shifts: tuple[str, ...] = SHIFTS
    benchmark = True

    def sample_scene(self, seed: int) -> Scene:
        return self.train_task(seed).scene

    @abc.abstractmethod
    def train_task(self, seed: int = 0) -> Task:
        """A task from the training distribution the base policy is cloned on."""

    @abc.abstractmethod
    def test_task(self, shift: str, seed: int) -> Task:
        """A shifted test task of kind `shift` (one of `shifts`)."""

    @abc.abstractmethod
    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        """n fresh tasks drawn from the R' of `task` (for evaluation after finetuning).

        layouts: "task" keeps the task's positions (R' is about how things look); "train"
        places the objects as a random training layout does, so success also asks whether
        what the policy learnt carries over to every layout it was trained on. The `other`
        shift varies positions beyond the training layouts either way.
        shifted: every task carries the task's shift (sim.core.carrying_shift); the rest of
        R' is drawn as usual.
        """

    @abc.abstractmethod
    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        """The scripted demonstrator's action in `scene`: float32 (A,) or int64 scalar."""

    def demonstrate(self, task: Task, *, noise: float = 0.0, seed: int = 0) -> Trajectory:
        """The scripted expert's closed-loop demonstration of `task` (expert_run), drawn."""
        scenes, actions = self.expert_run(task, noise=noise, seed=seed)
        obs = self.render_batch(scenes)  # (T+1, H, W, 3)
        return Trajectory(tuple(scenes), obs, actions, self.success(task, scenes))

    def expert_run(
        self, task: Task, *, noise: float = 0.0, seed: int = 0
    ) -> tuple[list[Scene], np.ndarray]:
        """The scenes (T+1) and the expert's actions (T, A) | (T,) of its closed-loop run of
        `task`, without frames. With `noise`, each step executes the expert's action plus
        Gaussian noise of that standard deviation (seeded, clipped to [-1, 1]) and records the
        expert's own action (continuous worlds)."""
        rng = np.random.default_rng([seed, 11])
        scenes, actions = [task.scene], []
        for _ in range(self.horizon):
            a = np.asarray(self.expert_action(task, scenes[-1]))
            done = a
            if noise > 0:
                done = np.clip(a + rng.normal(0.0, noise, a.shape), -1.0, 1.0).astype(a.dtype)
            scenes.append(self.step_batch([scenes[-1]], done[None])[0])
            actions.append(a)
        return scenes, np.stack(actions)
