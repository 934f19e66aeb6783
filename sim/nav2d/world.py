"""The 2D navigation world: tasks, shifts, dynamics, expert and success (design section 4)."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from sim.core import (
    PRESENCE,
    Concept,
    ConceptSpace,
    Obj,
    Reward,
    Scene,
    Slot,
    Task,
    Trajectory,
    World,
    carrying_shift,
    check_layouts,
    check_shift,
    draw_from_reward,
)
from sim.nav2d import render as R

START = (-5.0, 5.0)
GOAL = (5.0, -5.0)
# Training layouts (agent start, goal): every pair of distinct corners with the goal off the
# bottom-left corner. The start varies, so the policy must tell the agent from the goal by
# appearance; the bottom-left goal is never seen, which is what the `other` shift uses.
TRAIN_LAYOUTS = tuple((a, g) for g in R.CORNERS if g != (-5.0, -5.0) for a in R.CORNERS if a != g)
HORIZON = 20
SUCCESS_RADIUS = 1.0  # success: within this distance of the goal after the last step
AVOID_RADIUS = 2.0  # an avoided distractor must never be this close
COLOUR = Concept("colour", tuple(R.COLOURS))
SHAPE = Concept("shape", R.SHAPES)
SPACE = ConceptSpace(
    (
        Slot("goal", (COLOUR, SHAPE)),
        Slot("distractor", (COLOUR, SHAPE), optional=True),
    )
)


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    return float(np.hypot(a[0] - b[0], a[1] - b[1]))


class Nav2DWorld(World):
    """Go to the goal in 20 steps of (dx, dy) in [-1, 1]^2. Agent state: (x, y, t)."""

    name = "nav2d"
    space = SPACE
    horizon = HORIZON
    obs_shape = (R.SIZE_PX, R.SIZE_PX, 3)
    discrete = False
    action_dim = 2
    epsilon = 0.2
    lossless_frames = True

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
            [R.corner_index(o.pos) * len(R.SHAPES) + SHAPE.index(o.value("shape")) for o in shown],
            [COLOUR.index(o.value("colour")) for o in shown],
        )
        layer.flags.writeable = False
        return layer

    # -- dynamics -----------------------------------------------------------------------------
    def step_batch(self, scenes: Sequence[Scene], actions: np.ndarray) -> list[Scene]:
        actions = np.asarray(actions, np.float64)
        assert actions.shape == (len(scenes), 2), f"actions must be (B, 2), got {actions.shape}"
        agent = np.array([s.agent for s in scenes], np.float64)  # (B, 3): x, y, t
        live = agent[:, 2] < HORIZON
        xy = np.clip(agent[:, :2] + np.clip(actions, -1.0, 1.0), -R.ARENA, R.ARENA)
        agent[live, :2] = xy[live]
        agent[live, 2] += 1
        return [
            Scene(s.world, s.objects, tuple(float(v) for v in a))
            for s, a in zip(scenes, agent, strict=True)
        ]

    def done(self, scene: Scene) -> bool:
        return scene.agent[2] >= HORIZON

    def meets_reward(self, task: Task, scenes: Sequence[Scene]) -> bool:
        final = scenes[-1]
        if _dist(final.agent, final.obj("goal").pos) >= SUCCESS_RADIUS:
            return False
        for slot in task.reward.avoid:
            o = scenes[0].obj(slot)
            if o.present and min(_dist(s.agent, o.pos) for s in scenes) < AVOID_RADIUS:
                return False
        return True

    def expert_action(self, task: Task, scene: Scene) -> np.ndarray:
        """Straight to the goal, arriving exactly at the last step: (goal - pos) / steps left."""
        x, y, t = scene.agent
        left = max(HORIZON - t, 1.0)
        gx, gy = scene.obj("goal").pos
        return np.clip(np.array([(gx - x) / left, (gy - y) / left], np.float32), -1, 1)

    # -- tasks --------------------------------------------------------------------------------
    def _scene(
        self, goal_values, goal_pos=GOAL, distractor=None, distractor_pos=(5.0, 5.0), start=START
    ):
        present = distractor is not None
        d_values = distractor or goal_values
        return Scene(
            self.name,
            (
                Obj(
                    "goal", True, (("colour", goal_values[0]), ("shape", goal_values[1])), goal_pos
                ),
                Obj(
                    "distractor",
                    present,
                    (("colour", d_values[0]), ("shape", d_values[1])),
                    distractor_pos,
                ),
            ),
            (*start, 0.0),
        )

    def train_task(self, seed: int = 0) -> Task:
        """A training task: the red X and the agent on two corners (TRAIN_LAYOUTS[seed % 9]).

        Seed 0 is the canonical layout: agent top-left, goal bottom-right, no distractor.
        """
        start, goal = TRAIN_LAYOUTS[
            (seed + TRAIN_LAYOUTS.index((START, GOAL))) % len(TRAIN_LAYOUTS)
        ]
        scene = self._scene(("red", "X"), goal_pos=goal, start=start)
        return Task(self.name, scene, self._train_reward(), "train", seed)

    @staticmethod
    def _train_reward() -> Reward:
        return Reward(
            "go to the red X",
            frozenset({("goal", "colour"), ("goal", "shape")}),
            (("goal", "colour", ("red",)), ("goal", "shape", ("X",))),
        )

    def test_task(self, shift: str, seed: int) -> Task:
        check_shift(shift)
        rng = np.random.default_rng([seed, 2])
        train = self.train_task()
        goal = ("red", "X")
        if shift.startswith("object"):
            concept = (COLOUR, SHAPE)[rng.integers(2)]
            cur = goal[0] if concept is COLOUR else goal[1]
            new = str(rng.choice([v for v in concept.values if v != cur]))
            goal = (new, goal[1]) if concept is COLOUR else (goal[0], new)
            other = "shape" if concept is COLOUR else "colour"
            other_value = goal[1] if concept is COLOUR else goal[0]
            if shift == "object_ti":
                reward = Reward(
                    f"go to the {other_value} goal, whatever its {concept.name}",
                    frozenset({("goal", other)}),
                    (("goal", concept.name, concept.values), ("goal", other, (other_value,))),
                )
            else:
                reward = Reward(
                    f"go to the {goal[0]} {goal[1]}",
                    frozenset({("goal", "colour"), ("goal", "shape")}),
                    (("goal", "colour", (goal[0],)), ("goal", "shape", (goal[1],))),
                )
            return Task(self.name, self._scene(goal), reward, shift, seed, ("goal", concept.name))
        if shift.startswith("distractor"):
            d = (
                str(rng.choice([c for c in COLOUR.values if c != goal[0]])),
                str(rng.choice(SHAPE.values)),
            )
            pos = R.CORNERS[1 + rng.integers(2)]  # top-right or bottom-left: off the path
            scene = self._scene(goal, distractor=d, distractor_pos=pos)
            if shift == "distractor_ti":
                reward = Reward(
                    "go to the red X, ignore any distractor",
                    train.reward.relevant,
                    (
                        *train.reward.allowed,
                        ("distractor", PRESENCE, ("present", "absent")),
                        ("distractor", "colour", COLOUR.values),
                        ("distractor", "shape", SHAPE.values),
                    ),
                )
            else:
                reward = Reward(
                    f"go to the red X and keep clear of the {d[0]} {d[1]}",
                    train.reward.relevant
                    | {("distractor", PRESENCE), ("distractor", "colour"), ("distractor", "shape")},
                    (
                        *train.reward.allowed,
                        ("distractor", PRESENCE, ("present",)),
                        ("distractor", "colour", (d[0],)),
                        ("distractor", "shape", (d[1],)),
                    ),
                    avoid=("distractor",),
                )
            return Task(self.name, scene, reward, shift, seed, ("distractor", PRESENCE))
        # other: the same goal, in the bottom-left corner; no concept edit explains it
        reward = Reward(
            "go to the red X, wherever it is", train.reward.relevant, train.reward.allowed
        )
        return Task(self.name, self._scene(goal, goal_pos=(-5.0, -5.0)), reward, shift, seed)

    def fresh_tasks(
        self, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
    ) -> list[Task]:
        """Draw each open (slot, concept) of R' from its allowed values (keeping the shift,
        when `shifted`: sim.core.carrying_shift).

        The agent and goal keep the task's corners (layouts="task") or take a random training
        layout ("train"); a present distractor takes any free corner; for `other`, the
        corners vary over every pair.
        """
        check_layouts(layouts)
        rng = np.random.default_rng([seed, 3])
        layout_rng = np.random.default_rng([seed, 4])
        reward = carrying_shift(self.space, task) if shifted else task.reward
        tasks = []
        for i in range(n):
            scene = draw_from_reward(task.scene, reward, rng)
            g = scene.obj("goal")
            start, goal = tuple(scene.agent[:2]), g.pos
            if task.shift == "other":  # R' holds wherever the goal is
                start, goal = [(a, b) for a in R.CORNERS for b in R.CORNERS if a != b][
                    rng.integers(12)
                ]
                scene = Scene(scene.world, scene.objects, (*start, 0.0)).with_obj(
                    Obj(g.slot, True, g.values, goal)
                )
            elif layouts == "train":
                start, goal = TRAIN_LAYOUTS[layout_rng.integers(len(TRAIN_LAYOUTS))]
                scene = Scene(scene.world, scene.objects, (*start, 0.0)).with_obj(
                    Obj(g.slot, True, g.values, goal)
                )
            d = scene.obj("distractor")
            if d.present:
                free = [c for c in R.CORNERS if c not in (start, goal)]
                scene = scene.with_obj(Obj(d.slot, True, d.values, free[rng.integers(len(free))]))
            tasks.append(
                Task(self.name, scene, task.reward, task.shift, seed * 1000 + i, task.cause)
            )
        return tasks

    def placements(self, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
        """Free corners at least AVOID_RADIUS from every agent position of the demonstration."""
        taken = {o.pos for o in task.scene.objects if o.present and o.slot != slot}
        taken.add(tuple(task.scene.agent[:2]))
        return [
            c
            for c in R.CORNERS
            if c not in taken and min(_dist(s.agent, c) for s in demo.scenes) >= AVOID_RADIUS
        ]
