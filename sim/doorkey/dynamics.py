"""DoorKey dynamics on Scene values: minigrid's step rules, with any key opening any door.

The rules (minigrid.MiniGridEnv.step; sim.doorkey.env runs that code and the tests check that
both agree step for step):
    left/right: turn; forward: move unless the cell ahead is a wall, the key or a door that is
    not open (the goal and lava can be entered and end the episode);
    pickup: take the key from the cell ahead; drop: put the key on the empty cell ahead;
    toggle: the door ahead opens if locked and the agent holds a key (any colour), else an
    unlocked door flips between open and closed. Every step counts, even one that does nothing.
"""

from __future__ import annotations

from sim.core import Obj, Scene
from sim.doorkey.layout import (
    CLOSED,
    DIR_TO_VEC,
    DROP,
    FORWARD,
    LEFT,
    LOCKED,
    N_ACTIONS,
    OPEN,
    PICKUP,
    RIGHT,
    TOGGLE,
    State,
    agent_tuple,
    parse,
)

# what lies in a cell
EMPTY, WALL, KEY, DOOR, GOAL, LAVA = range(6)


def cell_kind(st: State, col: int, row: int) -> int:
    """What occupies (col, row) in state `st` (the agent itself is not an occupant)."""
    if (col, row) == st.door_cell:
        return DOOR
    if st.is_wall(col, row):
        return WALL
    if (col, row) == st.goal:
        return GOAL
    if not st.carrying and (col, row) == st.key:
        return KEY
    if st.lava_at((col, row)):
        return LAVA
    return EMPTY


def step_state(st: State, action: int) -> tuple[tuple[float, ...], tuple[int, int]]:
    """One step from a live state: the new agent tuple and the key's cell."""
    assert 0 <= action < N_ACTIONS, f"doorkey actions are 0..{N_ACTIONS - 1}, got {action}"
    col, row, d, carrying, door, key = st.col, st.row, st.dir, st.carrying, st.door, st.key
    dx, dy = DIR_TO_VEC[d]
    front = (col + dx, row + dy)
    ahead = cell_kind(st, *front)
    if action == LEFT:
        d = (d - 1) % 4
    elif action == RIGHT:
        d = (d + 1) % 4
    elif action == FORWARD:
        if ahead in (EMPTY, GOAL, LAVA) or (ahead == DOOR and door == OPEN):
            col, row = front
    elif action == PICKUP:
        if ahead == KEY:
            carrying = True
    elif action == DROP:
        if ahead == EMPTY and carrying:
            carrying, key = False, front
    elif action == TOGGLE and ahead == DOOR:
        if door == LOCKED:
            if carrying:
                door = OPEN
        else:
            door = CLOSED if door == OPEN else OPEN
    return agent_tuple(col, row, d, carrying, door, st.t + 1), key


def step_scene(scene: Scene, action: int) -> Scene:
    """The scene after `action`; a finished episode's scene comes back unchanged."""
    st = parse(scene)
    if st.done():
        return scene
    agent, key = step_state(st, int(action))
    objects = scene.objects
    if key != st.key:
        k = objects[0]
        objects = (Obj(k.slot, k.present, k.values, (float(key[0]), float(key[1]))), *objects[1:])
    return Scene(scene.world, objects, agent)
