"""DoorKey's grid, concept space and how a Scene holds its state (pure Python, no minigrid).

The grid is 12x12 cells, (col, row) with row 0 at the top, as minigrid counts them. Outer walls,
a wall down column 5; the key starts in column 3, the door sits in column 5, the goal in
column 10, each on a row 1..10; the agent starts at (1, 1) facing east.

Scene layout:
    objects: key, door, goal, lava0, lava1, lava2 (the slots of SPACE, in that order);
        Obj.pos = (col, row) as floats. A carried key keeps the cell it was picked up from.
        Absent lava slots keep a latent cell: where they appear when an edit adds them.
    agent: (col, row, dir, carrying, door, t) as floats:
        dir: 0 east, 1 south, 2 west, 3 north (minigrid's agent_dir);
        carrying: 1 while the agent holds the key, else 0;
        door: the door's state as minigrid encodes it: 0 open, 1 closed, 2 locked;
        t: steps taken so far (0..35).
    The episode is over when the agent stands on the goal (success), on a present lava tile
    (failure) or t reaches 35; all three follow from the Scene value alone.
"""

from __future__ import annotations

from dataclasses import dataclass

from sim.core import Obj, Scene
from sim.doorkey.concepts import (  # noqa: F401 (the names the rest of the world imports from here)
    COLOUR,
    LAVA_COLOUR,
    LAVA_COLOURS,
    LAVA_SLOTS,
    OBJ_COLOURS,
    OBJ_SLOTS,
    SLOT_NAMES,
    SPACE,
)

WORLD = "doorkey"
GRID = 12  # cells per side
TILE_PX = 3  # pixels per cell
SIZE_PX = GRID * TILE_PX  # 36
HORIZON = 35
WALL_COL = 5
KEY_COL, DOOR_COL, GOAL_COL = 3, 5, 10
ROWS = tuple(range(1, GRID - 1))  # rows an object may sit on: 1..10
START = (1, 1, 0)  # col, row, dir (east)

# actions: minigrid's Actions without `done`
LEFT, RIGHT, FORWARD, PICKUP, DROP, TOGGLE = range(6)
N_ACTIONS = 6
DIR_TO_VEC = ((1, 0), (0, 1), (-1, 0), (0, -1))  # minigrid's DIR_TO_VEC
OPEN, CLOSED, LOCKED = 0, 1, 2  # door states, minigrid's STATE_TO_IDX

COLUMNS = {"key": KEY_COL, "door": DOOR_COL, "goal": GOAL_COL}

Cell = tuple[int, int]  # (col, row)


@dataclass(frozen=True)
class State:
    """The integer view of a Scene that the dynamics, expert and renderer read."""

    col: int
    row: int
    dir: int
    carrying: bool
    door: int  # OPEN, CLOSED or LOCKED
    t: int
    key: Cell
    door_cell: Cell
    goal: Cell
    lava: tuple[tuple[Cell, int], ...]  # present lava tiles: (cell, index in LAVA_COLOURS)
    colours: tuple[int, int, int]  # key, door, goal: indices in OBJ_COLOURS

    @property
    def agent(self) -> Cell:
        return (self.col, self.row)

    def lava_at(self, cell: Cell) -> bool:
        return any(c == cell for c, _ in self.lava)

    def is_wall(self, col: int, row: int) -> bool:
        if col in (0, GRID - 1) or row in (0, GRID - 1):
            return True
        return col == WALL_COL and (col, row) != self.door_cell

    def done(self) -> bool:
        """Reached the goal, stepped on lava, or ran out of steps."""
        return self.t >= HORIZON or self.agent == self.goal or self.lava_at(self.agent)


def _cell(pos: tuple[float, ...]) -> Cell:
    return (int(pos[0]), int(pos[1]))


_PARSED: dict[int, tuple[Scene, State]] = {}  # id(scene) -> (scene, its State), lately parsed
PARSED_KEPT = 4096
_OBJ = {c: i for i, c in enumerate(OBJ_COLOURS)}
_LAVA = {c: i for i, c in enumerate(LAVA_COLOURS)}


def parse(scene: Scene) -> State:
    """The State of a doorkey Scene (its objects must be in SPACE's slot order). A scene met
    again soon (rendered, then checked for the end, then stepped) is parsed once."""
    hit = _PARSED.get(id(scene))
    if hit is not None and hit[0] is scene:
        return hit[1]
    if len(_PARSED) >= PARSED_KEPT:
        _PARSED.clear()
    st = _parse(scene)
    _PARSED[id(scene)] = (scene, st)
    return st


def _parse(scene: Scene) -> State:
    assert scene.world == WORLD and len(scene.objects) == len(SLOT_NAMES), (
        f"expected a {WORLD} scene with slots {SLOT_NAMES}, got {scene.world} "
        f"{[o.slot for o in scene.objects]}"
    )
    key, door, goal, *lavas = scene.objects
    col, row, d, carrying, door_state, t = scene.agent
    return State(
        int(col),
        int(row),
        int(d),
        bool(carrying),
        int(door_state),
        int(t),
        _cell(key.pos),
        _cell(door.pos),
        _cell(goal.pos),
        tuple((_cell(o.pos), _LAVA[o.values[0][1]]) for o in lavas if o.present),
        (_OBJ[key.values[0][1]], _OBJ[door.values[0][1]], _OBJ[goal.values[0][1]]),
    )


def agent_tuple(col: int, row: int, d: int, carrying: bool, door: int, t: int) -> tuple[float, ...]:
    return (float(col), float(row), float(d), float(carrying), float(door), float(t))


def make_scene(
    rows: dict[str, int],
    colours: dict[str, str],
    lavas: tuple[tuple[bool, str, Cell], ...],
) -> Scene:
    """An initial scene: key, door and goal on `rows` in their columns, with `colours`;
    lavas: three (present, colour, cell) for lava0..lava2. Agent at START, door locked."""
    assert len(lavas) == len(LAVA_SLOTS), f"need {len(LAVA_SLOTS)} lava entries, got {lavas}"
    objs = [
        Obj(s, True, (("colour", colours[s]),), (float(COLUMNS[s]), float(rows[s])))
        for s in OBJ_SLOTS
    ]
    objs += [
        Obj(s, present, (("colour", c),), (float(cell[0]), float(cell[1])))
        for s, (present, c, cell) in zip(LAVA_SLOTS, lavas, strict=True)
    ]
    return Scene(WORLD, tuple(objs), agent_tuple(*START, False, LOCKED, 0))


def rows_of(scene: Scene) -> dict[str, int]:
    return {s: int(scene.obj(s).pos[1]) for s in OBJ_SLOTS}


def interior() -> list[Cell]:
    """Every cell off the walls where a lava tile could lie, in row-major order."""
    return [(c, r) for r in ROWS for c in range(1, GRID - 1) if c != WALL_COL]
