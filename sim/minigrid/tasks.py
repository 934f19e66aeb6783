"""Tasks of a MiniGrid world, made from its concept space and its missions.

Training tasks are the environment's own layouts (reset seeds 0, 1, ...), as whoever trained a
policy on it saw them. Test tasks start from other layouts (seeds from 1,000,000 on) and change
the scene the way a shift kind says: object_ti recolours one or two objects the mission does
not name, distractor_ti adds the extra ball on a free cell off the expert's path, other moves
the agent's start (positions are outside the concept space). R' is the environment's own
reward for the layout's mission (fresh tasks keep the task's: layouts whose mission asks
something else are passed over): what the mission names (sim.minigrid.mission) is
task-relevant, the colours of the other objects and the added ball are left open, in any
colour but the ones the mission names for their type. Every task is one the expert solves
within the horizon; a draw it cannot solve is drawn again.
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
from sim.minigrid.concepts import COLOURED
from sim.minigrid.mission import Mission
from sim.minigrid.state import free_cells as open_cells

TEST_LAYOUTS = 1_000_000  # test tasks and fresh tasks start from layouts at or after this seed
MAX_TRIES = 200
SUCCESS = "env_reward"


def mission(world, layout: int) -> Mission:
    """The mission of layout `layout`, and what it names."""
    env, _, _ = world.layouts.get(int(layout))
    return Mission.of(env.mission)


def layout_reward(world, scene: Scene, shift: str, open_: tuple[tuple[str, str], ...]) -> Reward:
    """R' on the layout of `scene`: what its mission names is relevant; the (slot, concept)
    pairs of `open_` are left open (a colour: any but those the mission names for the slot's
    type; a presence: present or absent), and the instruction says so after the mission."""
    m = mission(world, int(scene.agent[0]))
    allowed = []
    for slot, concept in open_:
        kind = world.space.slot(slot).kind
        values = (PRESENT, ABSENT) if concept == PRESENCE else m.colours_for(kind)
        allowed.append((slot, concept, values))
    return Reward(
        f"{m.text}{_said(world, m, shift, open_)}",
        m.relevant(world.space, scene),
        tuple(allowed),
        success=SUCCESS,
    )


def _said(world, m: Mission, shift: str, open_) -> str:
    """What the instruction adds to the mission for a shift's open concepts."""
    if shift == "object_ti":
        parts = []
        for kind in sorted({world.space.slot(s).kind for s, _ in open_}):
            banned = m.banned(kind)
            parts.append(
                f"other {kind}s in any colour but {' or '.join(banned)}"
                if banned
                else f"whatever the {kind}'s colour"
            )
        return f" ({'; '.join(parts)})"
    if shift == "distractor_ti":
        banned = m.banned(world.space.slot(world.distractor).kind)
        but = f", but no other {' or '.join(banned)} ball" if banned else ""
        return f" (whatever else is on the floor{but})"
    if shift == "other":
        return " (from wherever it starts)"
    return ""


def train_task(world, seed: int = 0) -> Task:
    scene = world.layout_scene(seed)
    return Task(world.name, scene, layout_reward(world, scene, "train", ()), "train", seed)


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
    """Empty floor cells of the scene the agent can get to (no wall, no object, not the
    agent's; sim.minigrid.state.free_cells)."""
    with world.layouts.lock:
        env, _ = world.layouts.restore(scene)
        return open_cells(env)


def _solvable(world, scene: Scene) -> bool:
    """Solvable by the expert: first by a plan that drops nothing (a quick answer), else by
    any (PutNext missions need a drop)."""
    return (
        world.planner.plan(scene, thorough=False) is not None
        or world.planner.plan(scene) is not None
    )


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


def recolourable(world, scene: Scene) -> list:
    """The present objects of `scene` whose colour its mission leaves open."""
    relevant = mission(world, int(scene.agent[0])).relevant(world.space, scene)
    return [
        o
        for o in scene.objects
        if o.present
        and world.space.slot(o.slot).kind in COLOURED
        and (o.slot, "colour") not in relevant
    ]


def addable(world, scene: Scene) -> bool:
    """True when the mission of `scene` leaves the extra ball's presence open."""
    relevant = mission(world, int(scene.agent[0])).relevant(world.space, scene)
    return (world.distractor, PRESENCE) not in relevant


def roomy(world, scene: Scene) -> bool:
    """True when the scene has a free cell off the expert's path for the extra ball."""
    return bool(set(free_cells(world, scene)) - path_cells(world, scene))


def test_task(world, shift: str, seed: int) -> Task:
    """A shifted task of kind `shift` (world.shifts), from np.random.default_rng([seed, 2])."""
    check_shift(shift)
    if shift not in world.shifts:
        why = world.lacks.get(shift)
        raise UserError(
            f"{world.name} makes no {shift} tasks{f' ({why})' if why else ''}; accepted: "
            f"{', '.join(world.shifts)}"
        )
    rng = np.random.default_rng([seed, 2])
    for _ in range(MAX_TRIES):
        layout = TEST_LAYOUTS + int(rng.integers(TEST_LAYOUTS))
        base = world.layout_scene(layout)
        made = _shifted(world, base, shift, rng)
        if made is not None and _solvable(world, made[0]):
            scene, reward, cause = made
            return Task(world.name, scene, reward, shift, seed, cause)
    raise UserError(f"{world.name}: no solvable {shift} task in {MAX_TRIES} draws for seed {seed}")


def _shifted(world, base: Scene, shift: str, rng):
    if shift == "object_ti":
        coloured = recolourable(world, base)
        if not coloured:
            return None
        # one object, or two in one new colour (a key and its door only work together)
        k = min(len(coloured), 1 + int(rng.integers(2)))
        picked = [coloured[i] for i in rng.permutation(len(coloured))[:k]]
        open_ = tuple((o.slot, "colour") for o in picked)
        reward = layout_reward(world, base, shift, open_)
        olds = {o.value("colour") for o in picked}
        fits = set.intersection(*(set(v) for _, _, v in reward.allowed))
        others = [c for c in reward.allowed[0][2] if c in fits and c not in olds]
        if not others:
            return None
        new = str(others[int(rng.integers(len(others)))])
        changes = [Change(o.slot, "colour", o.value("colour"), new) for o in picked]
        scene = world.apply(base, Edit.of(*changes))
        return scene, reward, (changes[0].slot, "colour")
    if shift == "distractor_ti":
        slot = world.distractor
        if not addable(world, base):
            return None
        reward = layout_reward(world, base, shift, ((slot, PRESENCE), (slot, "colour")))
        colours = reward.allowed_values(slot, "colour")
        scene = _with_distractor(world, base, rng, slot, str(colours[rng.integers(len(colours))]))
        if scene is None:
            return None
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
    return scene, layout_reward(world, base, shift, ()), None


def fresh_tasks(world, task: Task, n: int, seed: int, *, shifted: bool = False) -> list[Task]:
    """n tasks on fresh layouts with the task's R', drawn from it (keeping the shift, when
    `shifted`: only layouts where the recoloured object is there): the open colours, the
    distractor (placed off the expert's path), the agent's start for `other`. Only layouts
    whose mission names the same objects, as the same slots, carry the same R' (GoToDoor's and
    Fetch's missions differ between layouts): the others are passed over. Drawn from
    np.random.default_rng([seed, 3])."""
    rng = np.random.default_rng([seed, 3])
    names = mission(world, int(task.scene.agent[0])).names
    reward = carrying_shift(world.space, task) if shifted else task.reward
    out: list[Task] = []
    for _ in range(MAX_TRIES * n):
        if len(out) == n:
            break
        layout = TEST_LAYOUTS + int(rng.integers(TEST_LAYOUTS))
        base = world.layout_scene(layout)
        m = mission(world, layout)
        if m.names != names or m.relevant(world.space, base) != task.reward.relevant:
            continue  # this layout's mission asks for something else
        if shifted and task.cause is not None:
            slot, concept = task.cause
            if concept != PRESENCE and not base.obj(slot).present:
                continue  # a layout without the recoloured object cannot carry its shift
        scene = _drawn(world, base, reward, rng)
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
        raise UserError(
            f"{world.name}: only {len(out)} of {n} fresh tasks were solvable on layouts whose "
            "mission asks what the task's does"
        )
    return out


def _drawn(world, scene: Scene, reward: Reward, rng) -> Scene | None:
    """`scene` with each concept R' leaves open drawn from its allowed values (an added
    distractor placed off the expert's path); None where it has no room."""
    for slot, concept, values in reward.allowed:  # the looks: onto this layout's objects
        v = str(values[int(rng.integers(len(values)))])
        o = scene.obj(slot)
        if concept == PRESENCE:
            if v == PRESENT and not o.present:
                placed = _with_distractor(
                    world, scene, rng, slot, o.values[0][1] if o.values else ""
                )
                if placed is None:
                    return None
                scene = placed
            elif v == ABSENT:
                scene = scene.with_obj(dataclasses.replace(o, present=False))
        elif o.present or slot == world.distractor:
            scene = scene.with_obj(o.with_value(concept, v))
    return scene


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
