"""DoorKey's minigrid objects and grid: any-key doors, pink lava, a white agent, 3-pixel tiles.

Everything here is minigrid's own object model and rendering functions, specialised:
    AnyKeyDoor: a Door that any Key unlocks (colour does not matter).
    PinkLava: Lava drawn pink, with its own `encode` so minigrid's tile cache keeps it apart.
    DoorKeyGrid: a Grid whose tiles draw the agent white and keep their own bounded cache.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX
from minigrid.core.grid import Grid
from minigrid.core.world_object import Door, Goal, Key, Lava, Wall, WorldObj
from minigrid.utils.rendering import (
    downsample,
    fill_coords,
    point_in_line,
    point_in_rect,
    point_in_triangle,
    rotate_fn,
)

from sim.doorkey.layout import (
    GRID,
    LAVA_COLOURS,
    LOCKED,
    OBJ_COLOURS,
    OPEN,
    TILE_PX,
    State,
)

AGENT_RGB = (255, 255, 255)
PINK_RGB = (255, 105, 180)
GRID_LINE_RGB = (100, 100, 100)


class AnyKeyDoor(Door):
    """A door that any key unlocks: otherwise key colour could never be task-irrelevant."""

    def toggle(self, env: Any, pos: tuple[int, int]) -> bool:
        if self.is_locked:
            if isinstance(env.carrying, Key):
                self.is_locked = False
                self.is_open = True
                return True
            return False
        self.is_open = not self.is_open
        return True


class PinkLava(Lava):
    """Lava in pink. Its `encode` (colour index of "purple", minigrid's nearest named colour)
    differs from orange Lava's, so tiles cached by encode never mix the two."""

    def __init__(self) -> None:
        super().__init__()
        self.color = "purple"

    def encode(self) -> tuple[int, int, int]:
        return (OBJECT_TO_IDX["lava"], COLOR_TO_IDX["purple"], 0)

    def render(self, img: np.ndarray) -> np.ndarray:
        fill_coords(img, point_in_rect(0, 1, 0, 1), PINK_RGB)
        for i in range(3):  # the same little waves as minigrid's Lava
            ylo = 0.3 + 0.2 * i
            yhi = 0.4 + 0.2 * i
            fill_coords(img, point_in_line(0.1, ylo, 0.3, yhi, r=0.03), (0, 0, 0))
            fill_coords(img, point_in_line(0.3, yhi, 0.5, ylo, r=0.03), (0, 0, 0))
            fill_coords(img, point_in_line(0.5, ylo, 0.7, yhi, r=0.03), (0, 0, 0))
            fill_coords(img, point_in_line(0.7, yhi, 0.9, ylo, r=0.03), (0, 0, 0))
        return img


def lava(colour: str) -> WorldObj:
    assert colour in LAVA_COLOURS, f"lava is {' or '.join(LAVA_COLOURS)}, not {colour!r}"
    return Lava() if colour == "orange" else PinkLava()


def door(colour: str, state: int) -> AnyKeyDoor:
    return AnyKeyDoor(colour, is_open=state == OPEN, is_locked=state == LOCKED)


class DoorKeyGrid(Grid):
    """minigrid's Grid with the agent drawn white and no view-cone highlighting."""

    # (encode, agent_dir, tile_size) -> uint8 (tile, tile, 3); bounded: the objects of this
    # world are finite (24 encodings x 5 agent overlays per tile size).
    tile_cache: dict[tuple[Any, ...], Any] = {}

    @classmethod
    def render_tile(
        cls,
        obj: WorldObj | None,
        agent_dir: int | None = None,
        highlight: bool = False,
        tile_size: int = TILE_PX,
        subdivs: int = 3,
    ) -> np.ndarray:
        """minigrid's Grid.render_tile with a white agent; `highlight` is not drawn."""
        key: tuple[Any, ...] = (agent_dir, tile_size, subdivs)
        key = obj.encode() + key if obj else key
        if key in cls.tile_cache:
            return cls.tile_cache[key]
        img = np.zeros((tile_size * subdivs, tile_size * subdivs, 3), np.uint8)
        fill_coords(img, point_in_rect(0, 0.031, 0, 1), GRID_LINE_RGB)
        fill_coords(img, point_in_rect(0, 1, 0, 0.031), GRID_LINE_RGB)
        if obj is not None:
            obj.render(img)
        if agent_dir is not None:
            tri_fn = point_in_triangle((0.12, 0.19), (0.87, 0.50), (0.12, 0.81))
            tri_fn = rotate_fn(tri_fn, cx=0.5, cy=0.5, theta=0.5 * math.pi * agent_dir)
            fill_coords(img, tri_fn, AGENT_RGB)
        img = downsample(img, subdivs)  # float mean, stored as uint8 as minigrid does
        tile = np.zeros((tile_size, tile_size, 3), np.uint8)
        tile[...] = img
        cls.tile_cache[key] = tile
        return tile

    def render(
        self,
        tile_size: int,
        agent_pos: tuple[int, int],
        agent_dir: int | None = None,
        highlight_mask: np.ndarray | None = None,
    ) -> np.ndarray:
        """The whole grid, uint8 (H, W, 3), row-major tiles; highlight_mask is ignored."""
        img = np.zeros((self.height * tile_size, self.width * tile_size, 3), np.uint8)
        for j in range(self.height):
            for i in range(self.width):
                here = (int(agent_pos[0]), int(agent_pos[1])) == (i, j)
                tile = self.render_tile(
                    self.get(i, j), agent_dir if here else None, tile_size=tile_size
                )
                img[j * tile_size : (j + 1) * tile_size, i * tile_size : (i + 1) * tile_size] = tile
        return img


def build_grid(st: State) -> DoorKeyGrid:
    """The minigrid grid of a state: walls, door, goal, key (unless carried), present lava."""
    grid = DoorKeyGrid(GRID, GRID)
    for j in range(GRID):
        for i in range(GRID):
            if st.is_wall(i, j):
                grid.set(i, j, Wall())
    key_c, door_c, goal_c = (OBJ_COLOURS[i] for i in st.colours)
    _put(grid, door(door_c, st.door), st.door_cell)
    _put(grid, Goal(goal_c), st.goal)
    if not st.carrying:
        _put(grid, Key(key_c), st.key)
    for cell, c in st.lava:
        _put(grid, lava(LAVA_COLOURS[c]), cell)
    return grid


def _put(grid: Grid, obj: WorldObj, cell: tuple[int, int]) -> None:
    grid.set(cell[0], cell[1], obj)
    obj.init_pos = obj.cur_pos = cell
