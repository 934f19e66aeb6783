"""Batched DoorKey rendering: 3x3 tiles from minigrid's own drawing code, composed with numpy.

Every tile the world can show (an object code x an agent overlay) is drawn once with
DoorKeyGrid.render_tile, the code minigrid's env renders with; a frame is then a gather of
12x12 tiles. The result equals DoorKeyEnv.render() pixel for pixel (tested).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from minigrid.core.world_object import Goal, Key, Wall, WorldObj

from sim.doorkey.layout import (
    GRID,
    LAVA_COLOURS,
    OBJ_COLOURS,
    SIZE_PX,
    TILE_PX,
    WALL_COL,
    State,
)
from sim.doorkey.objects import DoorKeyGrid, door, lava

N_DOOR_STATES = 3  # OPEN, CLOSED, LOCKED
N_COLOURS = len(OBJ_COLOURS)
# object codes: what a cell holds
C_EMPTY, C_WALL = 0, 1
C_KEY = 2  # + colour
C_DOOR = C_KEY + N_COLOURS  # + colour * N_DOOR_STATES + state
C_GOAL = C_DOOR + N_COLOURS * N_DOOR_STATES  # + colour
C_LAVA = C_GOAL + N_COLOURS  # + lava colour
N_CODES = C_LAVA + len(LAVA_COLOURS)


def _objects() -> list[WorldObj | None]:
    """The minigrid object of every code, in code order."""
    objs: list[WorldObj | None] = [None, Wall()]
    objs += [Key(c) for c in OBJ_COLOURS]
    objs += [door(c, s) for c in OBJ_COLOURS for s in range(N_DOOR_STATES)]
    objs += [Goal(c) for c in OBJ_COLOURS]
    objs += [lava(c) for c in LAVA_COLOURS]
    assert len(objs) == N_CODES
    return objs


def tile_table() -> np.ndarray:
    """uint8 (N_CODES, 5, 3, 3, 3): [code, overlay] with overlay 0 = no agent, 1 + agent dir."""
    table = np.zeros((N_CODES, 5, TILE_PX, TILE_PX, 3), np.uint8)
    for code, obj in enumerate(_objects()):
        for overlay in range(5):
            agent_dir = None if overlay == 0 else overlay - 1
            table[code, overlay] = DoorKeyGrid.render_tile(obj, agent_dir, tile_size=TILE_PX)
    return table


def _base_codes() -> np.ndarray:
    """int64 (12, 12) [row, col]: outer walls and the wall down column 5 (no door yet)."""
    codes = np.full((GRID, GRID), C_EMPTY, np.int64)
    codes[[0, -1], :] = C_WALL
    codes[:, [0, -1]] = C_WALL
    codes[:, WALL_COL] = C_WALL
    return codes


class Renderer:
    """Renders batches of States; holds the tile table (~2 KB) for its lifetime."""

    def __init__(self) -> None:
        self.tiles = tile_table()  # (N_CODES, 5, 3, 3, 3) uint8
        self.flat = self.tiles.reshape(N_CODES * 5, TILE_PX * TILE_PX * 3)  # [code * 5 + overlay]
        self.base = _base_codes().reshape(-1)  # (144,) int64

    def render_states(self, states: Sequence[State]) -> np.ndarray:
        """uint8 (B, 36, 36, 3) for B states."""
        b = len(states)
        codes = np.broadcast_to(self.base, (b, GRID * GRID)).copy()  # (B, 144) [row * 12 + col]
        rows, cells, values = [], [], []  # scatter lists for codes
        agent_cells, agent_dirs = np.empty(b, np.int64), np.empty(b, np.int64)
        for i, st in enumerate(states):
            kc, dc, gc = st.colours
            rows += [i, i]
            cells += [st.door_cell[1] * GRID + st.door_cell[0], st.goal[1] * GRID + st.goal[0]]
            values += [C_DOOR + dc * N_DOOR_STATES + st.door, C_GOAL + gc]
            if not st.carrying:
                rows.append(i)
                cells.append(st.key[1] * GRID + st.key[0])
                values.append(C_KEY + kc)
            for (c, r), lc in st.lava:
                rows.append(i)
                cells.append(r * GRID + c)
                values.append(C_LAVA + lc)
            agent_cells[i] = st.row * GRID + st.col
            agent_dirs[i] = st.dir
        codes[rows, cells] = values
        index = codes * 5  # (B, 144) rows of self.flat
        index[np.arange(b), agent_cells] += 1 + agent_dirs
        tiles = np.take(self.flat, index, axis=0)  # (B, 144, 27)
        tiles = tiles.reshape(b, GRID, GRID, TILE_PX, TILE_PX, 3)  # [b, row, col, y, x, rgb]
        return tiles.transpose(0, 1, 3, 2, 4, 5).reshape(b, SIZE_PX, SIZE_PX, 3)
