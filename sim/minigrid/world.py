"""A MiniGrid environment as a world, rendered and stepped by MiniGrid itself.

Name: `minigrid:<EnvId>[:tile=N][:view=full|partial]`, e.g. `minigrid:MiniGrid-DoorKey-5x5-v0`
or `minigrid:MiniGrid-DoorKey-5x5-v0:tile=12` (what `RGBImgObsWrapper(env, tile_size=12)`
shows a policy). Any id of gymnasium's registry that starts "MiniGrid-" works; nothing here
knows one environment from another.

Concepts  every object of the environment's grids is a slot of its type's kind (key0, door0,
          ball0, box0, goal0, lava0, ...): colour over MiniGrid's six (not lava), presence;
          one extra ball, absent, for distractors (sim.minigrid.concepts)
Actions   MiniGrid's own: 0 left, 1 right, 2 forward, 3 pickup, 4 drop, 5 toggle, 6 done
Shifts    object_ti (one or two objects the mission does not name recoloured), distractor_ti
          (the extra ball added off the expert's path), other (the agent starts elsewhere);
          every one solvable by the expert (sim.minigrid.tasks). A shift none of the first
          layouts can make (every object's colour named, a mission that takes any ball) is not
          offered, and `lacks` says why
Success   the environment's own reward is positive by the end of the episode; R' holds what
          the mission names relevant (sim.minigrid.mission)
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import gymnasium
import numpy as np

from sim.core import Benchmark, Key, Scene, Task, Trajectory, UserError
from sim.minigrid import concepts as C
from sim.minigrid import tasks as TK
from sim.minigrid.expert import Planner
from sim.minigrid.frames import TileFrames
from sim.minigrid.state import Layouts, sequenced

SHIFTS = ("object_ti", "distractor_ti", "other")
ACTION_KEYS = (
    Key("turn left", "arrowleft", 0),
    Key("turn right", "arrowright", 1),
    Key("forward", "arrowup", 2),
    Key("pick up", "P", 3),
    Key("drop", "D", 4),
    Key("toggle", "T", 5),
    Key("done", "Enter", 6),
)


PREFIXES = ("MiniGrid-", "BabyAI-")  # the ids minigrid registers
MAX_FRAME_PX = 256 * 256
"""The most pixels a frame may have: a search step holds a frame per live candidate (hundreds)
and a rollout one per step, so a frame's size is paid for many times over."""
LARGE_FRAME_BYTES = 64 * 1024  # frames from this size on get a line on what they cost
SEARCH_BATCH = 512  # candidates a search step typically renders at once (the cost line's)


def parse(name: str) -> tuple[str, int, str]:
    """(env id, tile size, view) of "<EnvId>[:tile=N][:view=full|partial]"."""
    env_id, *options = name.split(":")
    tile, view = 8, "full"
    for opt in options:
        key, _, value = opt.partition("=")
        if key == "tile" and value.isdigit() and 1 <= int(value) <= 64:
            tile = int(value)
        elif key == "view" and value in ("full", "partial"):
            view = value
        else:
            raise UserError(
                f"minigrid:{name}: unknown option {opt!r}; accepted: tile=N (1..64), "
                "view=full or view=partial"
            )
    if not env_id.startswith(PREFIXES) or env_id not in gymnasium.registry:
        import minigrid  # noqa: F401 (registers the MiniGrid ids)

        known = sorted(k for k in gymnasium.registry if k.startswith(PREFIXES))
        if env_id not in known:
            raise UserError(
                f"minigrid:{env_id}: not a registered MiniGrid or BabyAI environment; accepted: "
                f"{', '.join(known[:8])}, ... ({len(known)} ids)"
            )
    return env_id, tile, view


def frame_shape(env, tile: int, view: str) -> tuple[int, int, int]:
    """(H, W, 3) of env's frames at `tile` px per cell: the whole grid, or the agent's view."""
    if view == "partial":
        return (env.agent_view_size * tile, env.agent_view_size * tile, 3)
    return (env.height * tile, env.width * tile, 3)


def check_frames(name: str, shape: tuple[int, int, int], tile: int) -> None:
    """A UserError naming the largest tile that fits when frames of `shape` are over
    MAX_FRAME_PX pixels."""
    h, w, _ = shape
    if h * w <= MAX_FRAME_PX:
        return
    cells = (h // tile) * (w // tile)
    fits = max(1, int((MAX_FRAME_PX / cells) ** 0.5))
    raise UserError(
        f"{name}: frames of {h}x{w} pixels ({h * w * 3 / 2**20:.1f} MiB each, "
        f"{h * w * 3 * SEARCH_BATCH / 2**30:.1f} GiB for a search step of {SEARCH_BATCH} "
        f"candidates) are over the limit of {MAX_FRAME_PX:,} pixels; give tile={fits} or less"
    )


def cost_line(shape: tuple[int, int, int], horizon: int) -> str | None:
    """What frames of `shape` cost in memory, in one line, when they are large (else None)."""
    size = int(np.prod(shape))
    if size < LARGE_FRAME_BYTES:
        return None
    mib = lambda n: f"{n / 2**20:,.1f} MiB"  # noqa: E731
    return (
        f"frames are {shape[0]}x{shape[1]} pixels: {size / 1024:,.0f} KiB each, "
        f"{mib(size * SEARCH_BATCH)} for a search step of {SEARCH_BATCH} candidates, "
        f"{mib(size * (horizon + 1))} for one rollout of {horizon} steps (a smaller tile=N "
        "costs less)"
    )


def minigrid_world(rest: str) -> MiniGridWorld:
    """The registry's factory for names "minigrid:<rest>"."""
    env_id, tile, view = parse(rest)
    return MiniGridWorld(env_id, tile=tile, view=view)


class MiniGridWorld(Benchmark):
    """Any MiniGrid environment; see the module docstring."""

    discrete = True
    epsilon = 0.0
    lossless_frames = True
    demo_input = "keys"
    keys = ACTION_KEYS
    idle_action = 6  # done: changes nothing
    shifts = SHIFTS

    def __init__(self, env_id: str, *, tile: int = 8, view: str = "full") -> None:
        import minigrid  # noqa: F401 (registers the MiniGrid ids)

        self.env_id, self.tile, self.view = env_id, tile, view
        suffix = (f":tile={tile}" if tile != 8 else "") + (
            ":view=partial" if view != "full" else ""
        )
        self.name = f"minigrid:{env_id}{suffix}"
        probe = self._make()
        self.obs_shape = frame_shape(probe, tile, view)
        check_frames(self.name, self.obs_shape, tile)  # before any frame is drawn
        counts = C.count_objects(probe, range(C.SAMPLE_LAYOUTS))
        if sequenced(probe, range(C.SAMPLE_LAYOUTS)):
            raise UserError(
                f"{self.name}: its instructions are sequences (before, after, and) whose "
                "progress the environment keeps out of sight of a scene; give a BabyAI level "
                "of one instruction (GoTo, Open, Pickup, PutNext)"
            )
        self.space, self.distractor = C.space_for(counts)
        self.horizon = int(probe.max_steps)
        self.action_dim = int(probe.action_space.n)
        self.cost = cost_line(self.obs_shape, self.horizon)
        self.layouts = Layouts(self._make, self.space, self.name)
        self.tiles = TileFrames(tile)
        self.planner = Planner(self)
        self.shifts, self.lacks = self._offered()

    def _offered(self) -> tuple[tuple[str, ...], dict[str, str]]:
        """The shifts the first layouts can make, and why any other is not offered."""
        scenes = [self.layout_scene(s) for s in range(C.SAMPLE_LAYOUTS)]
        missions = {TK.mission(self, s).names for s in range(C.SAMPLE_LAYOUTS)}
        kinds = {k for names in missions for n in names for k in n.kinds()}
        self.mission_kinds = tuple(sorted(kinds)) if len(missions) > 1 else ()
        lacks = {}
        if not any(TK.recolourable(self, s) for s in scenes):
            lacks["object_ti"] = (
                "no TI object shift: the mission names the colour of every object that has one"
            )
        if not any(TK.addable(self, s) for s in scenes):
            lacks["distractor_ti"] = "no TI distractor: the mission takes any ball"
        elif not any(TK.roomy(self, s) for s in scenes):
            lacks["distractor_ti"] = "no free cell off the expert's path for an extra ball"
        if not any(TK.free_cells(self, s) for s in scenes):
            lacks["other"] = "no free cell the agent can reach to start from instead"
        return tuple(s for s in SHIFTS if s not in lacks), lacks

    def _make(self):
        return gymnasium.make(self.env_id).unwrapped

    # -- appearance ---------------------------------------------------------------------------
    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3): MiniGrid's get_frame of each scene, as its RGB wrappers show it."""
        if self.view == "full":  # the same pixels from MiniGrid's tiles (sim.minigrid.frames)
            with self.layouts.lock:
                cells = np.stack([self.tiles.cells(self.layouts.restore(s)[0]) for s in scenes])
            return self.tiles.frames(cells)
        out = np.empty((len(scenes), *self.obs_shape), np.uint8)
        with self.layouts.lock:
            for b, scene in enumerate(scenes):
                env, _ = self.layouts.restore(scene)
                out[b] = env.get_frame(highlight=env.highlight, tile_size=self.tile, agent_pov=True)
        return out

    # -- dynamics -----------------------------------------------------------------------------
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        actions = np.asarray(actions)
        assert actions.shape == (len(scenes),), f"actions must be (B,) ints, got {actions.shape}"
        return [self.step_one(s, int(a)) for s, a in zip(scenes, actions, strict=True)]

    @functools.lru_cache(maxsize=16384)  # noqa: B019 (one world per name and process)
    def step_one(self, scene: Scene, action: int) -> Scene:
        """The scene after MiniGrid's own step (a finished scene comes back unchanged). The
        environment's random generator is seeded from the layout and the step, so the
        dynamics are a function of the scene even where MiniGrid draws at random."""
        if self.done(scene):
            return scene
        if not 0 <= action < self.action_dim:
            raise UserError(f"{self.name}: action {action} is not one of 0..{self.action_dim - 1}")
        with self.layouts.lock:
            env, objs = self.layouts.restore(scene)
            env.np_random = np.random.default_rng([int(scene.agent[0]), int(scene.agent[5])])
            _, reward, terminated, truncated, _ = env.step(action)
            won = float(scene.agent[6] or reward > 0)
            done = float(terminated or truncated)
            layout = int(scene.agent[0])
            return self.layouts.read(env, objs, layout=layout, won=won, done=done, before=scene)

    def done(self, scene: Scene) -> bool:
        return scene.agent[7] > 0

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        return scenes[-1].agent[6] > 0

    # -- tasks --------------------------------------------------------------------------------
    def layout_scene(self, layout: int) -> Scene:
        """The initial scene of the environment reset with seed `layout`."""
        return self.layouts.get(int(layout))[2]

    def train_task(self, seed: int = 0) -> Task:
        return TK.train_task(self, seed)

    def test_task(self, shift: str, seed: int) -> Task:
        return TK.test_task(self, shift, seed)

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        return TK.fresh_tasks(self, task, n, seed, shifted=shifted)

    def task_for(self, scene: Scene) -> Task:
        """A task for a scene a user brings: R' is its layout's mission (sim.minigrid.mission)."""
        return Task(self.name, scene, TK.layout_reward(self, scene, "user", ()), "user", 0)

    def notes(self, task: Task) -> tuple[str, ...]:
        """A line on what large frames cost, and one when the task's mission names a target the
        frames alone do not single out."""
        m = TK.mission(self, int(task.scene.agent[0]))
        lines = [self.cost] if self.cost else []
        if m.hidden(self.space, task.scene, self.mission_kinds):
            lines.append(
                f'the mission "{m.text}" names the target, which the frames alone do not '
                "single out: a policy that sees only frames has to guess it"
            )
        return tuple(lines)

    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        plan = self.planner.plan(scene)
        return np.asarray(plan[0] if plan else self.idle_action, np.int64)

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        return TK.placements(self, task, slot, demo)

    def make_env(self):
        """The MiniGrid environment as a policy trained on it saw it: its RGB frames (the whole
        grid, or the agent's view) at this world's tile size."""
        from minigrid.wrappers import ImgObsWrapper, RGBImgObsWrapper, RGBImgPartialObsWrapper

        env = gymnasium.make(self.env_id)
        if self.view == "partial":
            return ImgObsWrapper(RGBImgPartialObsWrapper(env, tile_size=self.tile))
        return ImgObsWrapper(RGBImgObsWrapper(env, tile_size=self.tile))
