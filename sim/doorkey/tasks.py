"""DoorKey tasks: the training layouts, the five shifts, fresh tasks from R', lava placements.

Shifted tasks start from a training layout: undoing an object or distractor shift gives back a
training scene, and `other` moves the key or the door to a row no training layout has for it.
Every generated layout is solvable by the expert within the horizon: a layout it cannot solve
is rejected and drawn again from the same generator.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.core import (
    PRESENCE,
    Reward,
    Scene,
    Task,
    Trajectory,
    carrying_shift,
    check_layouts,
    check_shift,
)
from sim.doorkey.expert import path_cells, solvable
from sim.doorkey.layout import (
    COLUMNS,
    LAVA_COLOURS,
    LAVA_SLOTS,
    OBJ_COLOURS,
    OBJ_SLOTS,
    ROWS,
    SPACE,
    START,
    WORLD,
    Cell,
    interior,
    make_scene,
    parse,
    rows_of,
)

# The training layouts: (key, door, goal) rows, one per demonstration seed (expert: 15-29 steps).
# The goal's row takes all ten rows and the key's three, so the cloned policy cannot replay one
# action sequence: it has to find the key and the goal and read the scene from the image. Thirty
# layouts leave ten to hold out from finetuning whole (policy.heldout), so a run is scored on
# about ten distinct fresh tasks rather than three. The door keeps one row (a spread of all
# three rows needs about 5x the cloning budget to fit), so every other row of the door's and
# seven of the key's are places the training distribution never had: the `other` shift moves
# one there. Layout 0 is the canonical one.
TRAIN_LAYOUTS: tuple[tuple[int, int, int], ...] = tuple(
    (key, 3, goal) for key in (5, 4, 6) for goal in (8, 2, 4, 6, 3, 7, 5, 1, 9, 10)
)
TRAIN_COLOURS = {"key": "yellow", "door": "yellow", "goal": "green"}
# where absent lava slots wait to be added by an edit: the first of these that is free and off
# the expert's path (then any such cell, row by row)
LATENT_LAVA: tuple[Cell, ...] = ((8, 9), (2, 9), (7, 6), (2, 7), (8, 1), (7, 10))
MAX_TRIES = 1000
DOOR_REACH = 1  # present lava goes within this many cells (king moves) of the door, if it can

_PHRASE = {"key": "pick up the {} key", "door": "open the {} door", "goal": "go to the {} goal"}
_ANY = {
    "key": "pick up the key (any colour)",
    "door": "open the door (any colour)",
    "goal": "go to the goal (any colour)",
}

LavaSpec = tuple[tuple[bool, str], ...]  # (present, colour) for lava0..lava2
NO_LAVA: LavaSpec = ((False, "orange"),) * len(LAVA_SLOTS)


def neighbours(cell: Cell) -> set[Cell]:
    """The cell and its four neighbours: what keeping clear of a lava tile forbids."""
    c, r = cell
    return {(c, r), (c + 1, r), (c - 1, r), (c, r + 1), (c, r - 1)}


def unseen_rows(slot: str) -> tuple[int, ...]:
    """Rows on which no training layout has `slot` (where the `other` shift moves it)."""
    i = OBJ_SLOTS.index(slot)
    return tuple(r for r in ROWS if all(layout[i] != r for layout in TRAIN_LAYOUTS))


# -- rewards --------------------------------------------------------------------------------------
def _instruction(colours: dict[str, str], any_slot: str | None = None) -> str:
    """E.g. "pick up the yellow key, open the yellow door and go to the green goal"."""
    key, door, goal = (
        _ANY[s] if s == any_slot else _PHRASE[s].format(colours[s]) for s in OBJ_SLOTS
    )
    return f"{key}, {door} and {goal}"


def intent(task: Task) -> str:
    """What the user wants, naming only what R' holds fixed (World.intent): each object's
    colour when R' requires it ("open the door" when any colour will do; "open the door as
    it looks here" when R' requires the colour it was changed to), and "keep clear of
    anything else on the floor" when something is to be avoided."""
    fixed = {(s, c): v[0] for s, c, v in task.reward.allowed if len(v) == 1}
    parts = []
    for s in OBJ_SLOTS:
        colour = fixed.get((s, "colour"))
        if colour is None or (s, "colour") not in task.reward.relevant:
            parts.append(_PHRASE[s].format("").replace("  ", " "))
        elif task.cause == (s, "colour"):
            parts.append(_PHRASE[s].format("").replace("  ", " ") + " as it looks here")
        else:
            parts.append(_PHRASE[s].format(colour))
    text = f"{parts[0]}, {parts[1]} and {parts[2]}"
    return text + ("; keep clear of anything else on the floor" if task.reward.avoid else "")


def object_reward(colours: dict[str, str], *, ti_slot: str | None = None) -> Reward:
    """R' over key, door and goal colour; `ti_slot`'s colour is left open (task-irrelevant)."""
    return Reward(
        _instruction(colours, ti_slot),
        frozenset((s, "colour") for s in OBJ_SLOTS if s != ti_slot),
        tuple((s, "colour", OBJ_COLOURS if s == ti_slot else (colours[s],)) for s in OBJ_SLOTS),
    )


# -- layouts --------------------------------------------------------------------------------------
def _object_cells(rows: dict[str, int]) -> set[Cell]:
    return {(COLUMNS[s], rows[s]) for s in OBJ_SLOTS} | {START[:2]}


def build(
    rows: dict[str, int],
    colours: dict[str, str],
    lavas: LavaSpec,
    rng: np.random.Generator,
    *,
    keep_clear: tuple[str, ...] = (),
) -> Scene | None:
    """A solvable initial scene, or None when the expert cannot solve the layout in time.

    Present lava tiles lie close to the expert's path without changing it, where a distractor
    is in view of what the agent does: on a free cell next to the path, or, for slots in
    `keep_clear` (the agent must not step next to them), one cell further out; among those,
    the cells around the door first (DOOR_REACH): the door is where the agent turns and acts,
    and lava there is what changes the base policy's behaviour (measured over 50 distractor
    tasks: 30% solved with lava by the door, 78% with lava anywhere along the path). Absent
    ones get their latent cell (LATENT_LAVA).
    """
    base = make_scene(rows, colours, tuple((False, c, (0, 0)) for _, c in lavas))
    st = parse(base)
    if not solvable(st):
        return None
    path = set(path_cells(st))
    near = set().union(*(neighbours(c) for c in path))  # the path and the cells next to it
    free = [c for c in interior() if c not in path and c not in _object_cells(rows)]
    door = (COLUMNS["door"], rows["door"])
    cells: list[Cell | None] = [None] * len(LAVA_SLOTS)
    for i, (slot, (present, _)) in enumerate(zip(LAVA_SLOTS, lavas, strict=True)):
        if present:
            clear = near if slot in keep_clear else path
            ring = set().union(*(neighbours(c) for c in clear)) - clear
            ok = [c for c in free if c in ring and c not in cells]
            by_door = [c for c in ok if _chebyshev(c, door) <= DOOR_REACH]
            ok = by_door or ok
            if not ok:
                return None
            cells[i] = ok[rng.integers(len(ok))]
    for i, (present, _) in enumerate(lavas):
        if not present:
            pool = [c for c in LATENT_LAVA if c in free] + free
            cells[i] = next(c for c in pool if c not in cells)
    spec = tuple((p, c, cell) for (p, c), cell in zip(lavas, cells, strict=True))
    scene = make_scene(rows, colours, spec)  # type: ignore[arg-type]
    return scene if solvable(parse(scene)) else None


def _chebyshev(a: Cell, b: Cell) -> int:
    return max(abs(a[0] - b[0]), abs(a[1] - b[1]))


def _draw(make, what: str) -> Scene:
    for _ in range(MAX_TRIES):
        scene = make()
        if scene is not None:
            return scene
    raise RuntimeError(f"no solvable {what} layout in {MAX_TRIES} draws")


def _colours(scene: Scene) -> dict[str, str]:
    return {s: scene.obj(s).value("colour") for s in OBJ_SLOTS}


# -- tasks ----------------------------------------------------------------------------------------
def train_rows(seed: int = 0) -> dict[str, int]:
    """The key, door and goal rows of training layout `seed` (TRAIN_LAYOUTS, cycling)."""
    return dict(zip(OBJ_SLOTS, TRAIN_LAYOUTS[seed % len(TRAIN_LAYOUTS)], strict=True))


def train_task(seed: int = 0) -> Task:
    """A training task: yellow key and door, green goal, no lava, on the rows of
    TRAIN_LAYOUTS[seed % len(TRAIN_LAYOUTS)]. Seed 0 is the canonical layout (key 5, door 3,
    goal 8)."""
    scene = build(train_rows(seed), TRAIN_COLOURS, NO_LAVA, np.random.default_rng(0))
    assert scene is not None
    return Task(WORLD, scene, object_reward(TRAIN_COLOURS), "train", seed)


def shifted_task(shift: str, seed: int) -> Task:
    """A shifted task of kind `shift`, drawn from np.random.default_rng([seed, 2]).

    Every kind starts from one of the training layouts (drawn from the seed); the object and
    distractor shifts keep its rows, so undoing the shift gives back a training scene.
    """
    check_shift(shift)
    rng = np.random.default_rng([seed, 2])
    train = train_task(int(rng.integers(len(TRAIN_LAYOUTS))))
    rows, colours = rows_of(train.scene), dict(TRAIN_COLOURS)
    if shift.startswith("object"):
        slot = str(rng.choice(OBJ_SLOTS))
        colours[slot] = str(rng.choice([c for c in OBJ_COLOURS if c != colours[slot]]))
        scene = _draw(lambda: build(rows, colours, NO_LAVA, rng), shift)
        ti = slot if shift == "object_ti" else None
        return Task(WORLD, scene, object_reward(colours, ti_slot=ti), shift, seed, (slot, "colour"))
    if shift == "distractor_ti":
        n = int(rng.integers(1, len(LAVA_SLOTS) + 1))
        lavas = tuple((i < n, str(rng.choice(LAVA_COLOURS))) for i in range(len(LAVA_SLOTS)))
        scene = _draw(lambda: build(rows, colours, lavas, rng), shift)
        r = train.reward
        reward = Reward(
            f"{r.instruction}; any lava off the way does not matter",
            r.relevant,
            (
                *r.allowed,
                *((s, PRESENCE, ("present", "absent")) for s in LAVA_SLOTS),
                *((s, "colour", LAVA_COLOURS) for s in LAVA_SLOTS),
            ),
        )
        return Task(WORLD, scene, reward, shift, seed, (LAVA_SLOTS[0], PRESENCE))
    if shift == "distractor_tr":
        colour = str(rng.choice(LAVA_COLOURS))
        lavas = ((True, colour), *NO_LAVA[1:])
        slot = LAVA_SLOTS[0]
        scene = _draw(lambda: build(rows, colours, lavas, rng, keep_clear=(slot,)), shift)
        return Task(
            WORLD, scene, avoid_reward(train.reward, slot, colour), shift, seed, (slot, PRESENCE)
        )
    # other: one object moves to a row no training layout has for it; no concept edit explains it
    slot = str(rng.choice([s for s in OBJ_SLOTS if unseen_rows(s)]))

    def moved() -> Scene | None:
        new = dict(rows)
        new[slot] = int(rng.choice(unseen_rows(slot)))
        return build(new, colours, NO_LAVA, rng)

    scene = _draw(moved, shift)
    r = train.reward
    reward = Reward(f"{r.instruction}, wherever they are", r.relevant, r.allowed)
    return Task(WORLD, scene, reward, shift, seed)


def avoid_reward(train: Reward, slot: str, colour: str) -> Reward:
    """R' for distractor_tr: the training reward, and keep clear of `slot`, a `colour` lava."""
    return Reward(
        f"{train.instruction}; keep clear of the {colour} lava",
        train.relevant | {(slot, PRESENCE), (slot, "colour")},
        (*train.allowed, (slot, PRESENCE, ("present",)), (slot, "colour", (colour,))),
        avoid=(slot,),
    )


def fresh_tasks(
    task: Task, n: int, seed: int, layouts: str = "task", *, shifted: bool = False
) -> list[Task]:
    """n tasks from the R' of `task`: each allowed (slot, concept) drawn from its allowed values
    (keeping the shift, when `shifted`: sim.core.carrying_shift); the task's rows kept
    (layouts="task") or a random training layout's ("train"); for `other`, key, door and goal
    on random rows; present lava placed as `build` does. Drawn from
    np.random.default_rng([seed, 3]) (layouts from [seed, 4])."""
    check_layouts(layouts)
    rng = np.random.default_rng([seed, 3])
    layout_rng = np.random.default_rng([seed, 4])
    rows0, colours0 = rows_of(task.scene), _colours(task.scene)
    reward = carrying_shift(SPACE, task) if shifted else task.reward

    def one() -> Scene | None:
        colours = dict(colours0)
        lavas = [(task.scene.obj(s).present, task.scene.obj(s).value("colour")) for s in LAVA_SLOTS]
        for slot, concept, values in reward.allowed:
            v = str(values[rng.integers(len(values))])
            if slot in colours:
                colours[slot] = v
            else:
                i = LAVA_SLOTS.index(slot)
                p, c = lavas[i]
                lavas[i] = (v == "present", c) if concept == PRESENCE else (p, v)
        rows = dict(rows0)
        if layouts == "train":
            rows = train_rows(int(layout_rng.integers(len(TRAIN_LAYOUTS))))
        if task.shift == "other":
            rows = {s: int(rng.choice(ROWS)) for s in OBJ_SLOTS}
        return build(rows, colours, tuple(lavas), rng, keep_clear=task.reward.avoid)

    return [
        Task(WORLD, _draw(one, "fresh"), task.reward, task.shift, seed * 1000 + i, task.cause)
        for i in range(n)
    ]


def placements(task: Task, slot: str, demo: Trajectory) -> list[tuple[float, ...]]:
    """Cells for lava `slot` in every state of `demo` that change none of its steps: free of
    walls and other objects in every state and off every cell the agent stands on (and, for an
    avoided slot, off the cells next to them). Row-major (col, row) as floats."""
    assert slot in LAVA_SLOTS, f"only lava slots can be placed; {slot!r} is not one of {LAVA_SLOTS}"
    taken: set[Cell] = set()
    for scene in demo.scenes:
        st = parse(scene)
        taken |= neighbours(st.agent) if slot in task.reward.avoid else {st.agent}
        taken |= {st.door_cell, st.goal, st.key}
        taken |= {
            c for s, (c, _) in zip(_present_lava_slots(scene), st.lava, strict=True) if s != slot
        }
    return [(float(c), float(r)) for c, r in interior() if (c, r) not in taken]


def _present_lava_slots(scene: Scene) -> list[str]:
    return [s for s in LAVA_SLOTS if scene.obj(s).present]


def in_the_way(task: Task, slot: str) -> list[tuple[float, ...]]:
    """Cells for lava `slot` in the way of the expert's path through the task: each cell the
    agent stands on along it (the start and the objects' cells apart), then the free cells
    beside the path within DOOR_REACH of the door, where the distractor shifts put lava; only
    those that leave the task solvable (the expert goes round). Path order, as (col, row)
    floats; [] when the slot is there already."""
    assert slot in LAVA_SLOTS, f"only lava slots can be placed; {slot!r} is not one of {LAVA_SLOTS}"
    scene = task.scene
    if scene.obj(slot).present:
        return []
    st = parse(scene)
    path = path_cells(st)
    taken = {st.agent, st.key, st.door_cell, st.goal} | {c for c, _ in st.lava}
    door = st.door_cell
    beside = [
        c
        for c in interior()
        if c not in path
        and _chebyshev(c, door) <= DOOR_REACH
        and any(c in neighbours(p) for p in path)
    ]
    out: list[tuple[float, ...]] = []
    for cell in dict.fromkeys([*path, *beside]):
        if cell in taken:
            continue
        obj = scene.obj(slot)
        there = replace(obj, present=True, pos=(float(cell[0]), float(cell[1])))
        if solvable(parse(scene.with_obj(there))):
            out.append((float(cell[0]), float(cell[1])))
    return out
