"""nav2d's tasks: the training distribution, the five shifts, fresh tasks from R', and where an
added distractor may go."""

from __future__ import annotations

import numpy as np

from sim.core import (
    PRESENCE,
    Obj,
    Reward,
    Scene,
    Task,
    Trajectory,
    carrying_shift,
    check_layouts,
    check_shift,
    draw_from_reward,
)
from sim.nav2d import render as R
from sim.nav2d.concepts import COLOUR, SHAPE, SPACE
from sim.nav2d.dynamics import AVOID_RADIUS, dist

WORLD = "nav2d"
START = (-5.0, 5.0)
GOAL = (5.0, -5.0)
# Where a training task's agent may start: the four corners and four points inside, placed so
# that none lies within 1.25 units of the straight path from another start to a goal corner.
# The expert crosses the arena at a constant speed that depends on where it started, so a start
# on another start's path would show the same frame with two different actions.
STARTS: tuple[tuple[float, float], ...] = (
    *R.CORNERS,
    (0.0, 3.75),
    (3.75, 0.0),
    (-3.75, -1.25),
    (-1.25, -3.75),
)
# Training layouts (agent start, goal): the goal on a corner other than the bottom-left, the
# agent on any other start point (21). The start varies, so the policy must tell the agent from
# the goal by appearance, and a third of the layouts held out of finetuning (policy.heldout)
# still leaves several for evaluation; the bottom-left goal is never seen, which is what the
# `other` shift uses.
TRAIN_LAYOUTS = tuple((a, g) for g in R.CORNERS if g != (-5.0, -5.0) for a in STARTS if a != g)


def make_scene(goal_values, goal_pos=GOAL, distractor=None, distractor_pos=(5.0, 5.0), start=START):
    present = distractor is not None
    d_values = distractor or goal_values
    return Scene(
        WORLD,
        (
            Obj("goal", True, (("colour", goal_values[0]), ("shape", goal_values[1])), goal_pos),
            Obj(
                "distractor",
                present,
                (("colour", d_values[0]), ("shape", d_values[1])),
                distractor_pos,
            ),
        ),
        (*start, 0.0),
    )


def train_task(seed: int = 0) -> Task:
    """A training task: the red X on a corner and the agent on another start point
    (TRAIN_LAYOUTS, cycling).

    Seed 0 is the canonical layout: agent top-left, goal bottom-right, no distractor.
    """
    start, goal = TRAIN_LAYOUTS[(seed + TRAIN_LAYOUTS.index((START, GOAL))) % len(TRAIN_LAYOUTS)]
    scene = make_scene(("red", "X"), goal_pos=goal, start=start)
    return Task(WORLD, scene, train_reward(), "train", seed)


def train_reward() -> Reward:
    return Reward(
        "go to the red X",
        frozenset({("goal", "colour"), ("goal", "shape")}),
        (("goal", "colour", ("red",)), ("goal", "shape", ("X",))),
    )


def fixed_looks(reward: Reward) -> dict[tuple[str, str], str]:
    """{(slot, concept): value} of every look R' holds at one value."""
    return {(s, c): v[0] for s, c, v in reward.allowed if len(v) == 1 and c != PRESENCE}


def intent(task: Task) -> str:
    """What the user wants, naming only what R' holds fixed (World.intent): "go to the red
    X", "go to the red goal" (its shape open), "go to the goal as it looks here" (a changed
    look R' requires), "... and keep clear of anything else" (something to avoid)."""
    if task.cause in task.reward.relevant and task.cause[0] == "goal":
        text = "go to the goal as it looks here"
    else:
        fixed = fixed_looks(task.reward)
        words = (fixed.get(("goal", "colour")), fixed.get(("goal", "shape")) or "goal")
        text = "go to the " + " ".join(w for w in words if w)
    return text + (" and keep clear of anything else" if task.reward.avoid else "")


def test_task(shift: str, seed: int) -> Task:
    check_shift(shift)
    rng = np.random.default_rng([seed, 2])
    train = train_task()
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
        return Task(WORLD, make_scene(goal), reward, shift, seed, ("goal", concept.name))
    if shift.startswith("distractor"):
        d = (
            str(rng.choice([c for c in COLOUR.values if c != goal[0]])),
            str(rng.choice(SHAPE.values)),
        )
        pos = R.CORNERS[1 + rng.integers(2)]  # top-right or bottom-left: off the path
        scene = make_scene(goal, distractor=d, distractor_pos=pos)
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
        return Task(WORLD, scene, reward, shift, seed, ("distractor", PRESENCE))
    # other: the same goal, in the bottom-left corner; no concept edit explains it
    reward = Reward("go to the red X, wherever it is", train.reward.relevant, train.reward.allowed)
    return Task(WORLD, make_scene(goal, goal_pos=(-5.0, -5.0)), reward, shift, seed)


def fresh_tasks(
    task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
) -> list[Task]:
    """Draw each open (slot, concept) of R' from its allowed values (keeping the shift,
    when `shifted`: sim.core.carrying_shift).

    The agent and goal keep the task's places (layouts="task") or take a random training
    layout ("train"); a present distractor takes any free corner; for `other`, the
    corners vary over every pair.
    """
    check_layouts(layouts)
    rng = np.random.default_rng([seed, 3])
    layout_rng = np.random.default_rng([seed, 4])
    reward = carrying_shift(SPACE, task) if shifted else task.reward
    tasks = []
    for i in range(n):
        scene = draw_from_reward(task.scene, reward, rng)
        g = scene.obj("goal")
        start, goal = tuple(scene.agent[:2]), g.pos
        if task.shift == "other":  # R' holds wherever the goal is
            start, goal = [(a, b) for a in R.CORNERS for b in R.CORNERS if a != b][rng.integers(12)]
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
        tasks.append(Task(WORLD, scene, task.reward, task.shift, seed * 1000 + i, task.cause))
    return tasks


def placements(task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
    """Free corners at least AVOID_RADIUS from every agent position of the demonstration."""
    taken = {o.pos for o in task.scene.objects if o.present and o.slot != slot}
    taken.add(tuple(task.scene.agent[:2]))
    return [
        c
        for c in R.CORNERS
        if c not in taken and min(dist(s.agent, c) for s in demo.scenes) >= AVOID_RADIUS
    ]
