"""Tasks of a MiniGrid world, made from its concept space.

Training tasks are the environment's own layouts (reset seeds 0, 1, ...), as whoever trained a
policy on it saw them. Test tasks start from other layouts (seeds from 1,000,000 on) and change
the scene the way a shift kind says: object_ti recolours one or two objects, distractor_ti adds
the extra ball on a free cell off the expert's path, other moves the agent's start (positions
are outside the concept space). R' is the environment's own reward, which looks at no colour
and no distractor: those concepts are left open (task-irrelevant). Every task is one the
expert solves within the horizon; a draw it cannot solve is drawn again.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.core import (
    ABSENT,
    PRESENCE,
    PRESENT,
    Change,
    Edit,
    Reward,
    Scene,
    Task,
    Trajectory,
    UserError,
    carrying_shift,
    check_shift,
    draw_from_reward,
)
from sim.minigrid.concepts import COLOUR, COLOURED

TEST_LAYOUTS = 1_000_000  # test tasks and fresh tasks start from layouts at or after this seed
MAX_TRIES = 200


def mission(world, layout: int) -> str:
    env, _, _ = world.layouts.get(int(layout))
    return str(env.mission)


def train_task(world, seed: int = 0) -> Task:
    scene = world.layout_scene(seed)
    reward = Reward(mission(world, seed), frozenset(), success="env_reward")
    return Task(world.name, scene, reward, "train", seed)


def path_cells(world, scene: Scene) -> set[tuple[int, int]]:
    """The cells the expert's plan stands on and acts on (the cell in front of the agent)."""
    plan = world.planner.plan(scene)
    cells: set[tuple[int, int]] = set()
    s = scene
    for a in plan or ():
        cells |= _agent_and_front(s)
        s = world.step_one(s, a)
    return cells | _agent_and_front(s)


def _agent_and_front(scene: Scene) -> set[tuple[int, int]]:
    _, col, row, direction, *_ = scene.agent
    dx, dy = ((1, 0), (0, 1), (-1, 0), (0, -1))[int(direction)]
    return {(int(col), int(row)), (int(col) + dx, int(row) + dy)}


def free_cells(world, scene: Scene) -> list[tuple[int, int]]:
    """Empty floor cells of the scene (no wall, no object, not the agent's)."""
    env, _, _ = world.layouts.get(int(scene.agent[0]))
    with world.layouts.lock:
        env, _ = world.layouts.restore(scene)
        agent = (int(scene.agent[1]), int(scene.agent[2]))
        return [
            (i, j)
            for j in range(1, env.height - 1)
            for i in range(1, env.width - 1)
            if env.grid.get(i, j) is None and (i, j) != agent
        ]


def _solvable(world, scene: Scene) -> bool:
    """Solvable by a plan that drops nothing (what the expert's demonstration then follows)."""
    return world.planner.plan(scene, thorough=False) is not None


def _with_distractor(world, scene: Scene, rng, slot: str, colour: str) -> Scene | None:
    """The scene with `slot` added in `colour` on a free cell off the expert's path."""
    path = path_cells(world, scene)
    cells = [c for c in free_cells(world, scene) if c not in path]
    if not cells:
        return None
    col, row = cells[int(rng.integers(len(cells)))]
    o = scene.obj(slot)
    added = dataclasses.replace(
        o, present=True, values=(("colour", colour),), pos=(float(col), float(row), 0.0)
    )
    return scene.with_obj(added)


def test_task(world, shift: str, seed: int) -> Task:
    """A shifted task of kind `shift` (world.shifts), from np.random.default_rng([seed, 2])."""
    check_shift(shift)
    if shift not in world.shifts:
        raise UserError(f"{world.name} makes no {shift} tasks; accepted: {', '.join(world.shifts)}")
    rng = np.random.default_rng([seed, 2])
    for _ in range(MAX_TRIES):
        layout = TEST_LAYOUTS + int(rng.integers(TEST_LAYOUTS))
        base = world.layout_scene(layout)
        text = mission(world, layout)
        made = _shifted(world, base, shift, rng, text)
        if made is not None and _solvable(world, made[0]):
            scene, reward, cause = made
            return Task(world.name, scene, reward, shift, seed, cause)
    raise UserError(f"{world.name}: no solvable {shift} task in {MAX_TRIES} draws for seed {seed}")


def _shifted(world, base: Scene, shift: str, rng, text: str):
    if shift == "object_ti":
        coloured = [
            o for o in base.objects if o.present and world.space.slot(o.slot).kind in COLOURED
        ]
        if not coloured:
            return None
        # one object, or two in one new colour (a key and its door only work together)
        k = min(len(coloured), 1 + int(rng.integers(2)))
        picked = [coloured[i] for i in rng.permutation(len(coloured))[:k]]
        olds = {o.value("colour") for o in picked}
        others = [c for c in COLOUR.values if c not in olds]
        new = str(others[int(rng.integers(len(others)))])
        changes = [Change(o.slot, "colour", o.value("colour"), new) for o in picked]
        scene = world.apply(base, Edit.of(*changes))
        kinds = " and ".join(sorted({world.space.slot(c.slot).kind for c in changes}))
        reward = Reward(
            f"{text} (whatever the {kinds}'s colour)",
            frozenset(),
            tuple((c.slot, "colour", COLOUR.values) for c in changes),
            success="env_reward",
        )
        return scene, reward, (changes[0].slot, "colour")
    if shift == "distractor_ti":
        slot = world.distractor
        colour = str(COLOUR.values[int(rng.integers(len(COLOUR.values)))])
        scene = _with_distractor(world, base, rng, slot, colour)
        if scene is None:
            return None
        reward = Reward(
            f"{text} (whatever else is on the floor)",
            frozenset(),
            ((slot, PRESENCE, (PRESENT, ABSENT)), (slot, "colour", COLOUR.values)),
            success="env_reward",
        )
        return scene, reward, (slot, PRESENCE)
    # other: the agent starts on another cell, facing another way
    cells = free_cells(world, base)
    if not cells:
        return None
    col, row = cells[int(rng.integers(len(cells)))]
    a = base.agent
    scene = Scene(
        base.world, base.objects, (a[0], float(col), float(row), float(rng.integers(4)), *a[4:])
    )
    return (
        scene,
        Reward(f"{text} (from wherever it starts)", frozenset(), success="env_reward"),
        None,
    )


def fresh_tasks(world, task: Task, n: int, seed: int, *, shifted: bool = False) -> list[Task]:
    """n tasks on fresh layouts with R' drawn as the task's (keeping the shift, when
    `shifted`: only layouts that have the recoloured object): the recoloured objects'
    colours, the distractor (placed off the expert's path), the agent's start for `other`.
    Drawn from np.random.default_rng([seed, 3])."""
    rng = np.random.default_rng([seed, 3])
    reward = carrying_shift(world.space, task) if shifted else task.reward
    out: list[Task] = []
    for _ in range(MAX_TRIES * n):
        if len(out) == n:
            break
        layout = TEST_LAYOUTS + int(rng.integers(TEST_LAYOUTS))
        base = world.layout_scene(layout)
        recoloured = shifted and task.cause is not None and task.cause[1] != PRESENCE
        if recoloured and not base.obj(task.cause[0]).present:
            continue  # a layout without the recoloured object cannot carry its shift
        scene = base
        for slot, concept, values in reward.allowed:  # the looks: onto this layout's objects
            v = str(values[int(rng.integers(len(values)))])
            o = scene.obj(slot)
            if concept == PRESENCE:
                if v == PRESENT and not o.present:
                    placed = _with_distractor(
                        world, scene, rng, slot, o.values[0][1] if o.values else ""
                    )
                    if placed is None:
                        scene = None
                        break
                    scene = placed
                elif v == ABSENT:
                    scene = scene.with_obj(dataclasses.replace(o, present=False))
            elif o.present or slot == world.distractor:
                scene = scene.with_obj(o.with_value(concept, v))
        if scene is None:
            continue
        if task.shift == "other":
            cells = free_cells(world, scene)
            col, row = cells[int(rng.integers(len(cells)))]
            a = scene.agent
            scene = Scene(
                scene.world,
                scene.objects,
                (a[0], float(col), float(row), float(rng.integers(4)), *a[4:]),
            )
        if _solvable(world, scene):
            out.append(
                Task(world.name, scene, task.reward, task.shift, seed * 1000 + len(out), task.cause)
            )
    if len(out) < n:
        raise UserError(f"{world.name}: only {len(out)} of {n} fresh tasks were solvable")
    return out


def placements(world, task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
    """Free cells off the demonstrated path in every scene of the demonstration."""
    path: set[tuple[int, int]] = set()
    for s in demo.scenes:
        path |= _agent_and_front(s)
    ok = None
    for s in demo.scenes:
        cells = set(free_cells(world, s)) - path
        ok = cells if ok is None else ok & cells
    state = task.scene.obj(slot).pos[2] if len(task.scene.obj(slot).pos) > 2 else 0.0
    return [(float(c), float(r), state) for c, r in sorted(ok or ())]


__all__ = ["draw_from_reward", "fresh_tasks", "placements", "test_task", "train_task"]
