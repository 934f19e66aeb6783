"""The DoorKey expert: breadth-first search to the goal through key, door and goal.

The search runs over (col, row, dir, carrying, door) with the moves that make progress (turn,
forward, pick the key up, open the door); lava, walls, the key on the floor and a door that is
not open are obstacles, and the goal ends the search. Run closed loop, one search per step: the
first action of a shortest plan from the current state.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

from sim.doorkey.dynamics import EMPTY, GOAL, KEY, cell_kind, step_state
from sim.doorkey.layout import (
    CLOSED,
    DIR_TO_VEC,
    FORWARD,
    GRID,
    HORIZON,
    LEFT,
    LOCKED,
    OPEN,
    PICKUP,
    RIGHT,
    TOGGLE,
    Cell,
    State,
)

_ORDER = (FORWARD, LEFT, RIGHT, PICKUP, TOGGLE)  # fixed order: a deterministic plan
_PLANS: dict[tuple, tuple[int, ...] | None] = {}  # what a plan depends on -> the plan
PLANS_KEPT = 4096


def _static(st: State) -> list[int]:
    """Flat [row * 12 + col] cell kinds, with the key's cell as if it were on the floor."""
    kinds = []
    for r in range(GRID):
        for c in range(GRID):
            k = cell_kind(st, c, r)
            kinds.append(KEY if (c, r) == st.key and k == EMPTY else k)
    return kinds


def plan(st: State) -> list[int] | None:
    """A shortest action sequence from `st` that ends on the goal, or None if there is none.
    Planned once per layout and agent state (colours apart: the same lava cells in another
    slot or colour give the same plan)."""
    key = (*st.agent, st.dir, st.carrying, st.door, st.t, st.key, st.door_cell, st.goal)
    key += tuple(sorted(c for c, _ in st.lava))
    if key not in _PLANS:
        if len(_PLANS) >= PLANS_KEPT:
            _PLANS.clear()
        found = _plan(st)
        _PLANS[key] = None if found is None else tuple(found)
    cached = _PLANS[key]
    return None if cached is None else list(cached)


def _plan(st: State) -> list[int] | None:
    if st.done():
        return None
    kinds = _static(st)
    door_cell = st.door_cell
    start = (st.col, st.row, st.dir, st.carrying, st.door)
    parent: dict[tuple, tuple | None] = {start: None}
    via: dict[tuple, int] = {}
    queue = deque([start])
    while queue:
        s = queue.popleft()
        col, row, d, carrying, door = s
        dx, dy = DIR_TO_VEC[d]
        front = (col + dx, row + dy)
        fi = front[1] * GRID + front[0]
        ahead = kinds[fi]
        for a in _ORDER:
            nxt = None
            if a == LEFT:
                nxt = (col, row, (d - 1) % 4, carrying, door)
            elif a == RIGHT:
                nxt = (col, row, (d + 1) % 4, carrying, door)
            elif a == FORWARD:
                if ahead == GOAL:
                    return [*_unwind(parent, via, s), FORWARD]
                free = ahead == EMPTY or (ahead == KEY and carrying)
                if free or (front == door_cell and door == OPEN):
                    nxt = (front[0], front[1], d, carrying, door)
            elif a == PICKUP:
                if ahead == KEY and not carrying:
                    nxt = (col, row, d, True, door)
            elif front == door_cell and (door == CLOSED or (door == LOCKED and carrying)):
                nxt = (col, row, d, carrying, OPEN)  # TOGGLE
            if nxt is not None and nxt not in parent:
                parent[nxt] = s
                via[nxt] = a
                queue.append(nxt)
    return None


def _unwind(parent: dict, via: dict, s: tuple) -> list[int]:
    out = []
    while parent[s] is not None:
        out.append(via[s])
        s = parent[s]
    return out[::-1]


def solvable(st: State) -> bool:
    """The expert reaches the goal before the horizon."""
    p = plan(st)
    return p is not None and st.t + len(p) <= HORIZON


def path_cells(st: State) -> list[Cell]:
    """The cells the agent stands on along the expert's plan from `st`, start included."""
    p = plan(st)
    assert p is not None, "the expert cannot solve this layout"
    cells = [st.agent]
    for a in p:
        agent, key = step_state(st, a)
        col, row, d, carrying, door, t = (int(v) for v in agent)
        st = replace(st, col=col, row=row, dir=d, carrying=bool(carrying), door=door, t=t, key=key)
        if st.agent != cells[-1]:
            cells.append(st.agent)
    return cells
