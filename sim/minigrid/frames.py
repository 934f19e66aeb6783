"""MiniGrid's full-view frames, a batch at a time, from MiniGrid's own tiles.

`env.get_frame()` of the whole grid is a grid of tiles. A cell's tile is MiniGrid's
`Grid.render_tile` of what the cell holds, with the agent's triangle where the agent stands and
lighter where the agent sees (the highlight). So a batch of frames is the same pixels gathered
from a stack of tiles:

- each distinct tile is drawn once, by MiniGrid;
- which cells the agent sees comes from MiniGrid's own `gen_obs_grid`, once per agent pose and
  pattern of cells that can be seen through (the only things it depends on).

The frames are MiniGrid's pixel for pixel (tests/sim/test_minigrid.py compares them).
"""

from __future__ import annotations

import numpy as np
from minigrid.core.grid import Grid

CHUNK_BYTES = 16 * 2**20  # frames gathered at once, beside the batch's own
SEEN_MEMO = 65_536  # (agent pose, see-through pattern) -> cells seen, kept before starting over


class TileFrames:
    """Full-view frames of one MiniGrid environment's states at `tile` pixels per cell."""

    def __init__(self, tile: int) -> None:
        self.tile = tile
        self._index: dict[tuple, int] = {}  # render_tile's key -> row of the tile stack
        self._tiles: list[np.ndarray] = []  # (tile, tile, 3) uint8 each
        self._stack = np.zeros((0, tile, tile, 3), np.uint8)
        self._seen: dict[tuple, np.ndarray] = {}  # pose + see-through -> bool (W, H)

    def cells(self, env) -> np.ndarray:
        """int (H, W): the tile of each cell of env as it is now (the agent included)."""
        grid, w = env.grid, env.grid.width
        agent = int(env.agent_pos[1]) * w + int(env.agent_pos[0])  # its cell, in grid order
        direction = int(env.agent_dir)
        lit = self.seen(env).T.ravel().tolist() if env.highlight else [False] * len(grid.grid)
        rows = []
        for k, cell in enumerate(grid.grid):  # row by row, as Grid.grid holds them
            here = direction if k == agent else None
            key = (cell.encode() if cell is not None else ()) + (here, lit[k])
            row = self._index.get(key)
            if row is None:
                row = self._draw(key, cell, here, lit[k])
            rows.append(row)
        return np.array(rows, np.intp).reshape(grid.height, w)

    def _draw(self, key: tuple, cell, here: int | None, lit: bool) -> int:
        """Draw one more tile with MiniGrid; its row in the stack."""
        drawn = Grid.render_tile(cell, agent_dir=here, highlight=lit, tile_size=self.tile)
        tile = np.empty((self.tile, self.tile, 3), np.uint8)
        tile[...] = drawn  # floats cut to uint8 as Grid.render's assignment cuts them
        self._tiles.append(tile)
        self._index[key] = len(self._tiles) - 1
        return self._index[key]

    def seen(self, env) -> np.ndarray:
        """bool (W, H): the cells the agent sees, as env.get_full_render highlights them."""
        through = tuple(c is None or c.see_behind() for c in env.grid.grid)
        memo = (tuple(int(v) for v in env.agent_pos), int(env.agent_dir), through)
        hit = self._seen.get(memo)
        if hit is None:
            if len(self._seen) >= SEEN_MEMO:
                self._seen.clear()
            hit = self._seen[memo] = _highlight(env)
        return hit

    def frames(self, cells: np.ndarray) -> np.ndarray:
        """uint8 (B, H * tile, W * tile, 3) of the tiles `cells` int (B, H, W) name, gathered
        CHUNK_BYTES of frames at a time: the batch's frames and one chunk are all the memory
        it takes."""
        if len(self._stack) < len(self._tiles):
            self._stack = np.stack(self._tiles)  # (K, tile, tile, 3)
        b, h, w = cells.shape
        t = self.tile
        out = np.empty((b, h, t, w, t, 3), np.uint8)
        step = max(1, CHUNK_BYTES // out[0].nbytes)
        for i in range(0, b, step):
            gathered = self._stack[cells[i : i + step]]  # (b', H, W, tile, tile, 3)
            out[i : i + step] = gathered.transpose(0, 1, 3, 2, 4, 5)
        return out.reshape(b, h * t, w * t, 3)


def _highlight(env) -> np.ndarray:
    """bool (W, H): MiniGrid's highlight mask of the full view: each cell of the agent's view
    that gen_obs_grid finds visible, at its place on the grid."""
    _, visible = env.gen_obs_grid()  # (V, V) bool, [view column, view row]
    size = env.agent_view_size
    forward, right = np.asarray(env.dir_vec), np.asarray(env.right_vec)
    top_left = np.asarray(env.agent_pos) + forward * (size - 1) - right * (size // 2)
    vi, vj = np.nonzero(visible)
    at = top_left[None] - forward[None] * vj[:, None] + right[None] * vi[:, None]  # (N, 2)
    inside = (at[:, 0] >= 0) & (at[:, 0] < env.width) & (at[:, 1] >= 0) & (at[:, 1] < env.height)
    mask = np.zeros((env.width, env.height), bool)
    mask[at[inside, 0], at[inside, 1]] = True
    return mask
