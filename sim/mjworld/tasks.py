"""Tasks of a MuJoCo world, made from its concept space: the training task, the five shifts,
fresh tasks from R', and where a distractor may stand.

A package gives where its tasks start and what its table offers; everything else is here:

    world.reset_scene(seed, unseen=)  a scene from the environment's own reset: default looks,
                                      no distractor; `unseen`: its object where training never
                                      puts it (the `other` shift)
    world.workspace                   a Workspace (below)
    world.keep_clear(scene)           the (x, y) a distractor keeps CLEAR of: the objects, the
                                      goal, the gripper's start
    world.way(scene)                  (from, to) (x, y) of what the task carries, or None
    world.grip_pos(env)               float (3,): the gripper where the environment is now

Shifts    object_ti (one of `workspace.recoloured` recoloured; R' lets its colour go to any
          the other slots do not have: `told_apart`), object_tr (the `workspace.target`
          recoloured, R' names its colour; offered only where a task has a target),
          distractor_ti (a block coloured unlike the slots, added clear of the way),
          distractor_tr (the same beside the way; R' says leave it where it is), other (the
          object starts where training never put it)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sim.core import (
    ABSENT,
    PRESENCE,
    PRESENT,
    Obj,
    Reward,
    Scene,
    Task,
    Trajectory,
    UserError,
    carrying_shift,
    check_layouts,
    draw_from_reward,
)
from sim.mjworld.model import DISTRACTOR_HALF_M, PALETTE
from sim.mjworld.world import COLOUR

SUCCESS = "env"
DISTRACTOR = "distractor0"


@dataclass(frozen=True)
class Workspace:
    """Where a world's distractor may stand, and which slots its shifts recolour."""

    x_m: tuple[float, float]
    """Where on the table (x) a distractor may stand: within the arm's reach."""
    y_m: tuple[float, float]
    top_m: float
    """The table's top (z)."""
    recoloured: tuple[str, ...]
    """The slots object_ti may recolour."""
    target: tuple[str, str, str] | None = None
    """(slot, the words naming it in the instruction, its noun) of what object_tr recolours
    and R' names, e.g. ("target", "the target", "target"); None: no object_tr."""
    clear_m: float = 0.1
    """An added distractor keeps this far (x, y) from every point world.keep_clear gives."""
    beside_m: float = 0.11
    """A distractor in the way stands this far beside the middle of world.way."""


def offered_shifts(workspace: Workspace) -> tuple[str, ...]:
    """The shift kinds a world with this workspace makes."""
    from sim.core import SHIFTS

    return tuple(s for s in SHIFTS if s != "object_tr" or workspace.target is not None)


def initial_scene(world, env, like_pos: dict[str, tuple[float, ...]]) -> Scene:
    """The environment as it is (after a reset) as a scene: the model's own colours, each slot
    that does not move at `like_pos[slot]`, no distractor (parked, then placed at a clear spot
    should a shift bring it in)."""
    objs = []
    _, data = world.physics(env)
    for spec in world.slot_specs:
        pos = tuple(data.body(spec.body).xpos) if spec.moves else like_pos[spec.name]
        objs.append(Obj(spec.name, True, ((COLOUR, world.built[spec.name]),), pos))
    for d in world.distractors:
        objs.append(Obj(d, False, ((COLOUR, "blue"),), (0.0, 0.0, 0.0)))
    scene = world.scene_of(env, 0, Scene(world.name, tuple(objs), ()))
    return with_distractor_at(scene, clear_spot(world, scene, np.random.default_rng(0)))


def _spot(world, xy: np.ndarray) -> tuple[float, float, float]:
    return (float(xy[0]), float(xy[1]), world.workspace.top_m + DISTRACTOR_HALF_M)


def clear_spot(world, scene: Scene, rng, *, near_path: bool = False) -> tuple[float, ...]:
    """A place on the table for a distractor: clear_m from what matters (or, `near_path`,
    beside the way the task carries something)."""
    ws = world.workspace
    pts = world.keep_clear(scene)
    way = world.way(scene) if near_path else None
    if way is not None:
        a, b = (np.asarray(p, float) for p in way)
        mid = (a + b) / 2
        side = np.array([-(b - a)[1], (b - a)[0]])
        side = side / max(np.linalg.norm(side), 1e-9)
        for s in (1.0, -1.0):
            xy = mid + s * ws.beside_m * side
            on_table = ws.x_m[0] <= xy[0] <= ws.x_m[1] and ws.y_m[0] <= xy[1] <= ws.y_m[1]
            if on_table and min(np.linalg.norm(xy - b), np.linalg.norm(xy - a)) >= ws.beside_m:
                return _spot(world, xy)
    for _ in range(500):
        xy = np.array([rng.uniform(*ws.x_m), rng.uniform(*ws.y_m)])
        if all(np.linalg.norm(xy - p) >= ws.clear_m for p in pts):
            return _spot(world, xy)
    return _spot(world, np.array([ws.x_m[1], ws.y_m[1]]))


def with_distractor_at(
    scene: Scene, pos: tuple[float, ...], *, present: bool | None = None
) -> Scene:
    d = scene.obj(DISTRACTOR)
    return scene.with_obj(Obj(d.slot, d.present if present is None else present, d.values, pos))


def _fixed(world) -> list[tuple[str, str, tuple[str, ...]]]:
    return [(s.name, COLOUR, (world.built[s.name],)) for s in world.slot_specs]


def train_reward(world) -> Reward:
    allowed = _fixed(world)
    return Reward(
        world.instruction, frozenset((s, c) for s, c, _ in allowed), tuple(allowed), SUCCESS
    )


def train_task(world, seed: int = 0) -> Task:
    """The environment's own reset (its object in the training region), the model's own
    colours, no distractor."""
    return Task(world.name, world.reset_scene(seed), train_reward(world), "train", seed)


def told_apart(world, slot: str) -> tuple[str, ...]:
    """The colours `slot` may take and still be told apart from the world's other slots: the
    palette less every other slot's colour as built (a table the target's red hides the
    target from the camera; a block the cube's grey is a second cube)."""
    others = {world.built[s.name] for s in world.slot_specs if s.name != slot}
    return tuple(c for c in PALETTE if c not in others)


def _recoloured(world, scene: Scene, slot: str, rng) -> tuple[Scene, str]:
    options = [c for c in told_apart(world, slot) if c != scene.obj(slot).value(COLOUR)]
    colour = options[rng.integers(len(options))]
    return scene.with_obj(scene.obj(slot).with_value(COLOUR, colour)), colour


def test_task(world, shift: str, seed: int) -> Task:
    """A shifted task (one of world.shifts); the same (shift, seed) gives the same task."""
    if shift not in world.shifts:
        raise UserError(
            f"{world.name}: unknown shift {shift!r}; accepted: {', '.join(world.shifts)}"
        )
    ws = world.workspace
    rng = np.random.default_rng([seed, 7])
    scene = world.reset_scene(10_000 + seed, unseen=shift == "other")
    base = train_reward(world)
    allowed = list(base.allowed)
    if shift in ("object_ti", "object_tr"):
        if shift == "object_ti":
            slot = ws.recoloured[rng.integers(len(ws.recoloured))]
        else:
            slot = ws.target[0]
        scene, colour = _recoloured(world, scene, slot, rng)
        i = [s for s, _, _ in allowed].index(slot)
        if shift == "object_ti":
            allowed[i] = (slot, COLOUR, told_apart(world, slot))
            reward = Reward(
                f"{world.instruction}, whatever the {slot}'s colour",
                base.relevant - {(slot, COLOUR)},
                tuple(allowed),
                SUCCESS,
            )
        else:
            allowed[i] = (slot, COLOUR, (colour,))
            _, words, noun = ws.target
            text = world.instruction.replace(words, f"the {colour} {noun}")
            reward = Reward(text, base.relevant, tuple(allowed), SUCCESS)
        return Task(world.name, scene, reward, shift, seed, (slot, COLOUR))
    if shift.startswith("distractor"):
        tr = shift == "distractor_tr"
        others = told_apart(world, DISTRACTOR)
        colour = others[rng.integers(len(others))]
        d = scene.obj(DISTRACTOR).with_value(COLOUR, colour)
        scene = scene.with_obj(replace(d, present=True))
        scene = with_distractor_at(scene, clear_spot(world, scene, rng, near_path=tr))
        if tr:
            allowed += [(DISTRACTOR, PRESENCE, (PRESENT,)), (DISTRACTOR, COLOUR, (colour,))]
            reward = Reward(
                f"{world.instruction} without moving the {colour} block",
                base.relevant | {(DISTRACTOR, PRESENCE), (DISTRACTOR, COLOUR)},
                tuple(allowed),
                SUCCESS,
                avoid=(DISTRACTOR,),
            )
        else:
            allowed += [
                (DISTRACTOR, PRESENCE, (PRESENT, ABSENT)),
                (DISTRACTOR, COLOUR, others),
            ]
            reward = Reward(
                f"{world.instruction}, whatever else is on the table",
                base.relevant,
                tuple(allowed),
                SUCCESS,
            )
        return Task(world.name, scene, reward, shift, seed, (DISTRACTOR, PRESENCE))
    reward = replace(base, instruction=f"{world.instruction}, wherever it starts")
    return Task(world.name, scene, reward, shift, seed)


def fresh_tasks(
    world, task: Task, n: int, seed: int, *, layouts: str = "task", shifted: bool = False
) -> list[Task]:
    """n tasks from R' (or, `shifted`, from R' narrowed to carry the task's shift): looks drawn
    from the allowed values; places from new resets of the environment (in the training region,
    or beyond it for `other`; layouts "task" and "train" are the same here: every layout is
    the environment's own); a present distractor at a clear spot."""
    check_layouts(layouts)
    rng = np.random.default_rng([seed, 3])
    reward = carrying_shift(world.space, task) if shifted else task.reward
    out = []
    for i in range(n):
        fresh = world.reset_scene(20_000 + 1000 * seed + i, unseen=task.shift == "other")
        looks = draw_from_reward(task.scene, reward, rng)
        scene = Scene(
            world.name,
            tuple(
                Obj(o.slot, looks.obj(o.slot).present, looks.obj(o.slot).values, o.pos)
                for o in fresh.objects
            ),
            fresh.agent,
        )
        if scene.obj(DISTRACTOR).present:
            near = task.shift == "distractor_tr"
            scene = with_distractor_at(scene, clear_spot(world, scene, rng, near_path=near))
        out.append(Task(world.name, scene, task.reward, task.shift, seed * 1000 + i, task.cause))
    return out


def placements(world, task: Task, demo: Trajectory) -> list[tuple[float, ...]]:
    """Spots on the table where a distractor keeps clear_m from the objects, the goal and the
    gripper in every scene of the demonstration."""
    ws = world.workspace
    rng = np.random.default_rng(0)
    pts = []
    for s in demo.scenes:
        with world._lock:
            pts.append(np.array(world.grip_pos(world.restore(s))[:2]))
        pts += world.keep_clear(s)
    out = []
    for _ in range(400):
        xy = np.array([rng.uniform(*ws.x_m), rng.uniform(*ws.y_m)])
        if all(np.linalg.norm(xy - p) >= ws.clear_m for p in pts):
            out.append(_spot(world, xy))
        if len(out) == 8:
            break
    return out
