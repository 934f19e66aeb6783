"""Tabletop tasks: the training task, the five shifts, fresh tasks from R', and placements.

Pure Python on scenes (no MuJoCo). Objects sit at the centres of five areas of the table
(four quadrants and the centre), upright, rotation 0. Training layouts put the object and the
goal in two different quadrants that vary across seeds, so a policy cloned on them must tell the
object from the goal by appearance; the centre is never used in training, which is what the
`other` shift uses.
"""

from __future__ import annotations

from collections.abc import Sequence

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
    check_layouts,
    check_shift,
    draw_from_reward,
)
from sim.tabletop.catalogue import GOALS, MANIPULATED, SHAPES
from sim.tabletop.concepts import DISTRACTORS, space  # noqa: F401 (space: the world's)

WORLD = "tabletop"
VIEW_HALF_M = 0.4  # the camera sees, and actions address, the table square [-0.4, 0.4]^2
AREA_M = 0.23  # quadrant centres are at (+-AREA_M, +-AREA_M)
AREAS: dict[str, tuple[float, float]] = {
    "top-left": (-AREA_M, AREA_M),
    "top-right": (AREA_M, AREA_M),
    "bottom-left": (-AREA_M, -AREA_M),
    "bottom-right": (AREA_M, -AREA_M),
    "centre": (0.0, 0.0),
}
OBJECT_AREA, GOAL_AREA = "top-left", "bottom-right"
QUADRANTS = ("top-left", "top-right", "bottom-right", "bottom-left")  # clockwise
UNSEEN_AREA = "centre"  # no training layout uses it
# Training layouts (object area, goal area): the four diagonal ones and the four where the goal
# is the next quadrant clockwise. Given where either one is, the other can be in two places, so
# the policy has to find both by their looks. Seed 0 is the canonical layout.
TRAIN_LAYOUTS: tuple[tuple[str, str], ...] = (
    *((q, QUADRANTS[(i + 2) % 4]) for i, q in enumerate(QUADRANTS)),
    *((q, QUADRANTS[(i + 1) % 4]) for i, q in enumerate(QUADRANTS)),
)
assert TRAIN_LAYOUTS[0] == (OBJECT_AREA, GOAL_AREA)
TRAIN_OBJECT = ("flower", "red")  # (shape, colour)
TRAIN_GOAL = ("pan", "blue")
CLEAR_M = 0.15  # an added distractor keeps this far from every object and pick/place point
SUCCESS = "on_goal"


def pose(area_or_xy) -> tuple[float, ...]:
    """Obj.pos of an upright object resting on the table: (x, y, z, qw, qx, qy, qz), metres."""
    x, y = AREAS[area_or_xy] if isinstance(area_or_xy, str) else area_or_xy
    return (float(x), float(y), 0.0, 1.0, 0.0, 0.0, 0.0)


def _obj(slot: str, present: bool, look: tuple[str, str], area) -> Obj:
    return Obj(slot, present, (("shape", look[0]), ("colour", look[1])), pose(area))


def make_scene(
    obj: tuple[str, str] = TRAIN_OBJECT,
    goal: tuple[str, str] = TRAIN_GOAL,
    *,
    obj_area: str = OBJECT_AREA,
    goal_area: str = GOAL_AREA,
    distractors: Sequence[tuple[str, str, str]] = (),
) -> Scene:
    """A scene before the primitive (agent = (0.0,): no step taken).

    distractors: (shape, colour, area) for distractor0, distractor1 in order; absent slots take
    the object's appearance at the centre as their latent values.
    """
    objs = [_obj("object", True, obj, obj_area), _obj("goal", True, goal, goal_area)]
    for i, slot in enumerate(DISTRACTORS):
        if i < len(distractors):
            shape, colour, area = distractors[i]
            objs.append(_obj(slot, True, (shape, colour), area))
        else:
            objs.append(_obj(slot, False, obj, "centre"))
    return Scene(WORLD, tuple(objs), (0.0,))


def _describe(look: tuple[str, str]) -> str:
    return f"{look[1]} {look[0]}"


def intent(task: Task) -> str:
    """What the user wants, naming only what R' holds fixed (World.intent): "put the red
    flower on the blue pan", "... on the blue goal" (its shape open), "... on the goal as it
    looks here" (a changed look R' requires), "... without touching anything else"."""
    fixed = {(s, c): v[0] for s, c, v in task.reward.allowed if len(v) == 1}
    names = {}
    for slot in ("object", "goal"):
        shape, colour = fixed.get((slot, "shape")), fixed.get((slot, "colour"))
        if task.cause is not None and task.cause[0] == slot and task.cause in task.reward.relevant:
            names[slot] = f"{slot} as it looks here"
        else:
            names[slot] = " ".join(w for w in (colour, shape or slot) if w)
    sep = ", " if names["object"].endswith(" here") else " "
    text = f"put the {names['object']}{sep}on the {names['goal']}"
    return text + (" without touching anything else" if task.reward.avoid else "")


def train_reward() -> Reward:
    o, g = TRAIN_OBJECT, TRAIN_GOAL
    return Reward(
        f"put the {_describe(o)} on the {_describe(g)}",
        frozenset(
            {("object", "shape"), ("object", "colour"), ("goal", "shape"), ("goal", "colour")}
        ),
        (
            ("object", "shape", (o[0],)),
            ("object", "colour", (o[1],)),
            ("goal", "shape", (g[0],)),
            ("goal", "colour", (g[1],)),
        ),
        success=SUCCESS,
    )


def train_layout(seed: int) -> tuple[str, str]:
    """(object area, goal area) of training seed `seed`: TRAIN_LAYOUTS in turn."""
    return TRAIN_LAYOUTS[seed % len(TRAIN_LAYOUTS)]


def train_task(seed: int = 0) -> Task:
    """Fixed shapes and colours, no distractor; the object and the goal in the quadrants of
    train_layout(seed) (seed 0: the object top-left, the goal bottom-right)."""
    oa, ga = train_layout(seed)
    return Task(WORLD, make_scene(obj_area=oa, goal_area=ga), train_reward(), "train", seed)


def _layout(rng: np.random.Generator) -> tuple[str, str]:
    """A training layout drawn at random: test tasks keep the training positions."""
    return TRAIN_LAYOUTS[rng.integers(len(TRAIN_LAYOUTS))]


def _pick(rng: np.random.Generator, values: Sequence[str], exclude: Sequence[str] = ()) -> str:
    pool = [v for v in values if v not in exclude]
    return str(pool[rng.integers(len(pool))])


def _object_shift(shift: str, seed: int, rng, colours: Sequence[str]) -> Task:
    oa, ga = _layout(rng)
    looks = {"object": list(TRAIN_OBJECT), "goal": list(TRAIN_GOAL)}
    slot = ("object", "goal")[rng.integers(2)]
    concept = ("shape", "colour")[rng.integers(2)]
    k = 0 if concept == "shape" else 1
    options = colours if concept == "colour" else (MANIPULATED if slot == "object" else GOALS)
    looks[slot][k] = _pick(rng, options, exclude=[looks[slot][k]])
    o, g = tuple(looks["object"]), tuple(looks["goal"])
    allowed = [
        ("object", "shape", (o[0],)),
        ("object", "colour", (o[1],)),
        ("goal", "shape", (g[0],)),
        ("goal", "colour", (g[1],)),
    ]
    relevant = {(s, c) for s, c, _ in allowed}
    if shift == "object_ti":
        i = [(s, c) for s, c, _ in allowed].index((slot, concept))
        allowed[i] = (slot, concept, tuple(options))
        relevant.discard((slot, concept))
        desc = {"object": _describe(o), "goal": _describe(g)}
        look = o if slot == "object" else g
        desc[slot] = f"{look[1]} {slot}" if concept == "shape" else look[0]
        text = f"put the {desc['object']} on the {desc['goal']}, whatever the {slot}'s {concept}"
    else:
        text = f"put the {_describe(o)} on the {_describe(g)}"
    reward = Reward(text, frozenset(relevant), tuple(allowed), success=SUCCESS)
    scene = make_scene(o, g, obj_area=oa, goal_area=ga)
    return Task(WORLD, scene, reward, shift, seed, (slot, concept))


def _distractor_shift(shift: str, seed: int, rng, colours: Sequence[str]) -> Task:
    oa, ga = _layout(rng)
    n = 1 + int(rng.random() < 0.5)
    areas = [a for a in AREAS if a not in (oa, ga)]
    chosen = [areas[i] for i in rng.permutation(len(areas))[:n]]
    shapes = [s for s in SHAPES if s not in (TRAIN_OBJECT[0], TRAIN_GOAL[0])]
    cols = [c for c in colours if c not in (TRAIN_OBJECT[1], TRAIN_GOAL[1])]
    ds = [(_pick(rng, shapes), _pick(rng, cols), area) for area in chosen]
    scene = make_scene(obj_area=oa, goal_area=ga, distractors=ds)
    base = train_reward()
    if shift == "distractor_ti":
        allowed = list(base.allowed)
        for slot in DISTRACTORS:
            allowed += [
                (slot, PRESENCE, (PRESENT, ABSENT)),
                (slot, "shape", tuple(shapes)),
                (slot, "colour", tuple(cols)),
            ]
        reward = Reward(
            base.instruction + ", whatever else is on the table",
            base.relevant,
            tuple(allowed),
            success=SUCCESS,
        )
    else:
        slots = DISTRACTORS[:n]
        allowed = list(base.allowed)
        for slot, (shape, colour, _) in zip(slots, ds, strict=True):
            allowed += [
                (slot, PRESENCE, (PRESENT,)),
                (slot, "shape", (shape,)),
                (slot, "colour", (colour,)),
            ]
        names = " and the ".join(_describe(d[:2]) for d in ds)
        reward = Reward(
            base.instruction + f" without touching the {names}",
            base.relevant | {(s, c) for s in slots for c in (PRESENCE, "shape", "colour")},
            tuple(allowed),
            success=SUCCESS,
            avoid=slots,
        )
    return Task(WORLD, scene, reward, shift, seed, ("distractor0", PRESENCE))


def test_task(shift: str, seed: int, colours: Sequence[str]) -> Task:
    """A shifted task (sim.core.task.SHIFTS); the same (shift, seed) gives the same task."""
    check_shift(shift)
    rng = np.random.default_rng([seed, 7])
    if shift.startswith("object"):
        return _object_shift(shift, seed, rng, colours)
    if shift.startswith("distractor"):
        return _distractor_shift(shift, seed, rng, colours)
    # other: the object or the goal of a training layout moves to the centre, where no
    # training task put anything; no concept edit explains it
    oa, ga = _layout(rng)
    if rng.integers(2) == 0:
        oa = UNSEEN_AREA
    else:
        ga = UNSEEN_AREA
    scene = make_scene(obj_area=oa, goal_area=ga)
    base = train_reward()
    reward = Reward(
        base.instruction + ", wherever they are", base.relevant, base.allowed, success=SUCCESS
    )
    return Task(WORLD, scene, reward, shift, seed)


def _area_of(obj: Obj) -> str:
    for name, (x, y) in AREAS.items():
        if abs(obj.pos[0] - x) < 1e-6 and abs(obj.pos[1] - y) < 1e-6:
            return name
    raise ValueError(f"{obj.slot} is not at an area centre: {obj.pos[:2]}")


def fresh_tasks(
    task: Task, n: int, seed: int, layouts: str = "task", *, draw: Reward | None = None
) -> list[Task]:
    """n tasks drawn from R' (or from `draw`, a narrower reward such as
    sim.core.carrying_shift's): each open (slot, concept) from its allowed values; the
    object and goal in the task's areas (layouts="task") or a random training layout's
    ("train"); present distractors in random free areas; for `other`, the object and goal in
    random areas."""
    check_layouts(layouts)
    rng = np.random.default_rng([seed, 3])
    layout_rng = np.random.default_rng([seed, 4])
    reward = draw or task.reward
    out = []
    for i in range(n):
        scene = draw_from_reward(task.scene, reward, rng)
        areas = list(AREAS)
        if task.shift == "other":
            order = rng.permutation(len(areas))
            oa, ga = areas[order[0]], areas[order[1]]
        elif layouts == "train":
            oa, ga = TRAIN_LAYOUTS[layout_rng.integers(len(TRAIN_LAYOUTS))]
        else:
            oa, ga = _area_of(scene.obj("object")), _area_of(scene.obj("goal"))
        for slot, area in (("object", oa), ("goal", ga)):
            scene = scene.with_obj(Obj(slot, True, scene.obj(slot).values, pose(area)))
        free = [a for a in areas if a not in (oa, ga)]
        order = rng.permutation(len(free))
        for j, slot in enumerate(DISTRACTORS):
            d = scene.obj(slot)
            if d.present:
                scene = scene.with_obj(Obj(slot, True, d.values, pose(free[order[j]])))
        out.append(Task(WORLD, scene, task.reward, task.shift, seed * 1000 + i, task.cause))
    return out


def placements(task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
    """Area poses where `slot` can be added to every scene of the demonstration: at least
    CLEAR_M from every other present object in any of its scenes and from every pick and
    place point of its actions."""
    points = [o.pos[:2] for s in demo.scenes for o in s.objects if o.present and o.slot != slot]
    for a in np.asarray(demo.actions, float).reshape(-1, 4):
        points += [tuple(a[:2]), tuple(a[2:])]
    pts = np.array(points, float).reshape(-1, 2)
    out = []
    for xy in AREAS.values():
        if len(pts) == 0 or np.min(np.hypot(*(pts - np.array(xy)).T)) >= CLEAR_M:
            out.append(pose(xy))
    return out
