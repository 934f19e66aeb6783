"""Fetch tasks: training tasks from the environment's own resets, the five shifts, fresh tasks
from R', and where a distractor can be added.

Positions come from the environment's own reset (its object and goal sampling), seeded; the
training distribution keeps the resets whose object (the goal, in Reach) lies at most
TRAIN_MAX_DX_M beyond the gripper's start along x, and `other` keeps those at least
UNSEEN_MIN_DX_M beyond it, where no training task puts it.
"""

from __future__ import annotations

from dataclasses import replace

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
    carrying_shift,
    check_layouts,
    check_shift,
    draw_from_reward,
)
from sim.mjworld.model import DISTRACTOR_HALF_M, PALETTE
from sim.mjworld.world import COLOUR

TRAIN_MAX_DX_M = 0.05
UNSEEN_MIN_DX_M = 0.10
TABLE_TOP_M = 0.4
TABLE_X_M, TABLE_Y_M = (1.12, 1.48), (0.5, 1.0)  # where a distractor may stand (reachable)
BESIDE_M = 0.11  # a distractor in the way stands this far beside the object's way
CLEAR_M = 0.1  # an added distractor keeps this far (x, y) from the object, goal and gripper
SUCCESS = "env"
RESETS_TRIED = 200  # env seeds tried for one task before giving up


def _dx(world, env, scene: Scene) -> float:
    """How far beyond the gripper's start, along x, the object (the goal in Reach) starts."""
    where = scene.obj("object").pos if "object" in world.built else world.goal_of(scene)
    return float(where[0] - env.initial_gripper_xpos[0])


def _reset(world, seed: int, *, unseen: bool = False) -> Scene:
    """A scene from the environment's own reset: the first of its seeds [seed, k] whose object
    lies in the training region (or, `unseen`, beyond it); default looks, no distractor."""
    with world._lock:
        env = world._open()
        for k in range(RESETS_TRIED):
            env.reset(seed=int(np.random.SeedSequence([seed, k]).generate_state(1)[0]))
            scene = _as_scene(world, env)
            dx = _dx(world, env, scene)
            if (dx >= UNSEEN_MIN_DX_M) if unseen else (dx <= TRAIN_MAX_DX_M):
                return scene
    raise RuntimeError(f"{world.name}: no reset of seed {seed} puts the object where asked")


def _as_scene(world, env) -> Scene:
    goal = world.goal(env)
    objs = []
    for spec in world.slot_specs:
        pos = tuple(env.data.body(spec.body).xpos) if spec.moves else tuple(goal)
        objs.append(Obj(spec.name, True, ((COLOUR, world.built[spec.name]),), pos))
    for d in world.distractors:
        objs.append(Obj(d, False, ((COLOUR, "blue"),), (0.0, 0.0, 0.0)))
    like = Scene(world.name, tuple(objs), ())
    scene = world.scene_of(env, 0, like)
    return _with_distractor_at(scene, _clear_spot(world, scene, np.random.default_rng(0)))


def _points(world, scene: Scene) -> list[np.ndarray]:
    """The (x, y) a distractor must keep clear of: the object, the goal, the gripper's start."""
    pts = [world.goal_of(scene)[:2]]
    if "object" in world.built:
        pts.append(np.asarray(scene.obj("object").pos[:2]))
    with world._lock:
        pts.append(np.asarray(world._open().initial_gripper_xpos[:2]))
    return pts


def _clear_spot(world, scene: Scene, rng, *, near_path: bool = False) -> tuple[float, ...]:
    """A place on the table for a distractor: CLEAR_M from what matters (or, `near_path`,
    beside the way from the object to the goal)."""
    pts = _points(world, scene)
    if near_path and len(pts) == 3:
        goal, obj = pts[0], pts[1]
        mid = (goal + obj) / 2
        side = np.array([-(goal - obj)[1], (goal - obj)[0]])
        side = side / max(np.linalg.norm(side), 1e-9)
        for s in (1.0, -1.0):
            xy = mid + s * BESIDE_M * side
            on_table = (
                TABLE_X_M[0] <= xy[0] <= TABLE_X_M[1] and TABLE_Y_M[0] <= xy[1] <= TABLE_Y_M[1]
            )
            if on_table and min(np.linalg.norm(xy - goal), np.linalg.norm(xy - obj)) >= BESIDE_M:
                return (float(xy[0]), float(xy[1]), TABLE_TOP_M + DISTRACTOR_HALF_M)
    for _ in range(500):
        xy = np.array([rng.uniform(*TABLE_X_M), rng.uniform(*TABLE_Y_M)])
        if all(np.linalg.norm(xy - p) >= CLEAR_M for p in pts):
            return (float(xy[0]), float(xy[1]), TABLE_TOP_M + DISTRACTOR_HALF_M)
    return (TABLE_X_M[1], TABLE_Y_M[1], TABLE_TOP_M + DISTRACTOR_HALF_M)


def _on_table(xy: np.ndarray) -> bool:
    return TABLE_X_M[0] <= xy[0] <= TABLE_X_M[1] and TABLE_Y_M[0] <= xy[1] <= TABLE_Y_M[1]


def _with_distractor_at(
    scene: Scene, pos: tuple[float, ...], *, present: bool | None = None
) -> Scene:
    d = scene.obj("distractor0")
    return scene.with_obj(Obj(d.slot, d.present if present is None else present, d.values, pos))


def _fixed(world) -> list[tuple[str, str, tuple[str, ...]]]:
    return [(s.name, COLOUR, (world.built[s.name],)) for s in world.slot_specs]


def train_reward(world) -> Reward:
    allowed = _fixed(world)
    return Reward(
        world.instruction, frozenset((s, c) for s, c, _ in allowed), tuple(allowed), SUCCESS
    )


def train_task(world, seed: int = 0) -> Task:
    """The environment's own reset (object in the training region), the model's own colours,
    no distractor."""
    return Task(world.name, _reset(world, seed), train_reward(world), "train", seed)


def _recoloured(world, scene: Scene, slot: str, rng) -> tuple[Scene, str]:
    taken = {scene.obj(s.name).value(COLOUR) for s in world.slot_specs}
    options = [c for c in PALETTE if c not in taken]
    colour = options[rng.integers(len(options))]
    return scene.with_obj(scene.obj(slot).with_value(COLOUR, colour)), colour


def test_task(world, shift: str, seed: int) -> Task:
    """A shifted task; the same (shift, seed) gives the same task."""
    check_shift(shift)
    rng = np.random.default_rng([seed, 7])
    scene = _reset(world, 10_000 + seed, unseen=shift == "other")
    base = train_reward(world)
    allowed = list(base.allowed)
    if shift in ("object_ti", "object_tr"):
        movable = ["object", "table"] if "object" in world.built else ["table"]
        slot = movable[rng.integers(len(movable))] if shift == "object_ti" else "target"
        scene, colour = _recoloured(world, scene, slot, rng)
        i = [s for s, _, _ in allowed].index(slot)
        if shift == "object_ti":
            allowed[i] = (slot, COLOUR, tuple(PALETTE))
            reward = Reward(
                f"{world.instruction}, whatever the {slot}'s colour",
                base.relevant - {(slot, COLOUR)},
                tuple(allowed),
                SUCCESS,
            )
        else:
            allowed[i] = (slot, COLOUR, (colour,))
            text = world.instruction.replace("the target", f"the {colour} target")
            reward = Reward(text, base.relevant, tuple(allowed), SUCCESS)
        return Task(world.name, scene, reward, shift, seed, (slot, COLOUR))
    if shift.startswith("distractor"):
        tr = shift == "distractor_tr"
        others = [c for c in PALETTE if c not in {world.built[s.name] for s in world.slot_specs}]
        colour = others[rng.integers(len(others))]
        d = scene.obj("distractor0").with_value(COLOUR, colour)
        scene = scene.with_obj(replace(d, present=True))
        scene = _with_distractor_at(scene, _clear_spot(world, scene, rng, near_path=tr))
        if tr:
            allowed += [("distractor0", PRESENCE, (PRESENT,)), ("distractor0", COLOUR, (colour,))]
            reward = Reward(
                f"{world.instruction} without moving the {colour} block",
                base.relevant | {("distractor0", PRESENCE), ("distractor0", COLOUR)},
                tuple(allowed),
                SUCCESS,
                avoid=("distractor0",),
            )
        else:
            allowed += [
                ("distractor0", PRESENCE, (PRESENT, ABSENT)),
                ("distractor0", COLOUR, tuple(PALETTE)),
            ]
            reward = Reward(
                f"{world.instruction}, whatever else is on the table",
                base.relevant,
                tuple(allowed),
                SUCCESS,
            )
        return Task(world.name, scene, reward, shift, seed, ("distractor0", PRESENCE))
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
        fresh = _reset(world, 20_000 + 1000 * seed + i, unseen=task.shift == "other")
        looks = draw_from_reward(task.scene, reward, rng)
        scene = Scene(
            world.name,
            tuple(
                Obj(o.slot, looks.obj(o.slot).present, looks.obj(o.slot).values, o.pos)
                for o in fresh.objects
            ),
            fresh.agent,
        )
        if scene.obj("distractor0").present:
            near = task.shift == "distractor_tr"
            scene = _with_distractor_at(scene, _clear_spot(world, scene, rng, near_path=near))
        out.append(Task(world.name, scene, task.reward, task.shift, seed * 1000 + i, task.cause))
    return out


def placements(world, task: Task, demo: Trajectory) -> list[tuple[float, ...]]:
    """Spots on the table where a distractor keeps CLEAR_M from the object, the goal and the
    gripper in every scene of the demonstration."""
    rng = np.random.default_rng(0)
    pts = []
    for s in demo.scenes:
        with world._lock:
            env = world.restore(s)
            pts.append(np.array(env.data.site("robot0:grip").xpos[:2]))
        pts += _points(world, s)
    out = []
    for _ in range(400):
        xy = np.array([rng.uniform(*TABLE_X_M), rng.uniform(*TABLE_Y_M)])
        if all(np.linalg.norm(xy - p) >= CLEAR_M for p in pts):
            out.append((float(xy[0]), float(xy[1]), TABLE_TOP_M + DISTRACTOR_HALF_M))
        if len(out) == 8:
            break
    return out
