"""Top views of tabletop objects, and where their pixels go in a frame.

A `TopView` is one object's pixels seen from above (those that differ from the bare table),
relative to the pixel it stands on. `ViewIndex` answers, fast and memoised, the two questions
compositing asks of views: where a view's pixels land in the frame, and whether two views come
within a pixel of each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.core import Obj

Key = tuple[str, str]  # (shape, appearance)
PIXEL = np.dtype((np.void, 3))  # one RGB pixel: scatters move whole pixels, twice as fast
GRID_TOL_PX = 1e-6  # a coordinate this close to a whole pixel is on the grid
MEMO = 8192  # views whose flat offsets and footprint numbers are kept (a few KiB each)
MEETS = 100_000  # pairs of footprints whose meeting is kept


@dataclass(frozen=True)
class TopView:
    """One object's pixels seen from above: those that differ from the bare table.

    rows, cols int16 (N,): each pixel's place relative to the pixel the object stands on;
    colours uint8 (N, 3); near bool (h, w): the footprint grown by one pixel (8-neighbourhood),
    its first row and column at (top, left) relative to the object's pixel.
    """

    rows: np.ndarray  # (N,) int16
    cols: np.ndarray  # (N,) int16
    colours: np.ndarray  # (N, 3) uint8
    top: int
    left: int
    near: np.ndarray  # (h, w) bool

    @property
    def nbytes(self) -> int:
        return self.rows.nbytes + self.cols.nbytes + self.colours.nbytes + self.near.nbytes


def grid_pixel(o: Obj, px_per_m: float) -> tuple[int, int] | None:
    """(row, col) of an upright object on the pixel grid, relative to the frame's centre (rows
    grow downwards, y upwards); None for any other pose."""
    x, y, z, qw, qx, qy, qz = o.pos
    if z != 0.0 or (qw, qx, qy, qz) != (1.0, 0.0, 0.0, 0.0):
        return None
    c, r = x * px_per_m, -y * px_per_m
    rc, rr = round(c), round(r)
    if abs(c - rc) > GRID_TOL_PX or abs(r - rr) > GRID_TOL_PX:
        return None
    return int(rr), int(rc)


def same(a: TopView, b: TopView) -> bool:
    return (a.top, a.left) == (b.top, b.left) and all(
        np.array_equal(x, y)
        for x, y in ((a.rows, b.rows), (a.cols, b.cols), (a.colours, b.colours), (a.near, b.near))
    )


def grow(mask: np.ndarray) -> np.ndarray:
    """bool (h + 2, w + 2): mask grown by one pixel in all eight directions."""
    h, w = mask.shape
    out = np.zeros((h + 2, w + 2), bool)
    for dr in range(3):
        for dc in range(3):
            out[dr : dr + h, dc : dc + w] |= mask
    return out


class ViewIndex:
    """Memoised facts about views in frames of `size_px`: their flat pixel indices and whether
    two of them meet. A view is known by its identity while it is held here; `footprint` gives
    one number to every view of the same pixels and place (one shape in any colour)."""

    def __init__(self, size_px: int) -> None:
        self.size_px = size_px
        self._meets: dict[tuple, bool] = {}  # (footprint a, b, d row, d col) -> they meet
        self._footprints: dict[tuple, int] = {}  # a view's place, masks and pixels -> number
        self._fid: dict[int, tuple] = {}  # id(view) -> (view, its footprint's number)
        self._flat: dict[int, tuple] = {}  # id(view) -> (view, flat offsets, box, colours)

    def clear(self) -> None:
        self._meets.clear()
        self._footprints.clear()
        self._fid.clear()
        self._flat.clear()

    def meet(self, va: TopView, pa: tuple[int, int], vb: TopView, pb: tuple[int, int]) -> bool:
        """Whether the grown footprints of view a at pixel pa and view b at pb share a pixel."""
        dr, dc = pb[0] - pa[0], pb[1] - pa[1]
        memo = (self.footprint(va), self.footprint(vb), dr, dc)
        hit = self._meets.get(memo)
        if hit is None:
            # b's grown mask in a's grown mask's frame
            ha, wa = va.near.shape
            hb, wb = vb.near.shape
            r = vb.top + dr - va.top
            c = vb.left + dc - va.left
            r0, r1, c0, c1 = max(0, r), min(ha, r + hb), max(0, c), min(wa, c + wb)
            hit = (
                r0 < r1  # the boxes overlap: look at the pixels
                and c0 < c1
                and bool((va.near[r0:r1, c0:c1] & vb.near[r0 - r : r1 - r, c0 - c : c1 - c]).any())
            )
            if len(self._meets) > MEETS:
                self._meets.clear()
            self._meets[memo] = hit
        return hit

    def footprint(self, v: TopView) -> int:
        """A number for v's pixels and grown footprint and their place, shared by every view of
        the same (most often: one shape in any colour)."""
        hit = self._fid.get(id(v))
        if hit is None or hit[0] is not v:
            if len(self._fid) >= MEMO:
                self._fid.clear()
            if len(self._footprints) >= MEMO:  # the numbers start again: so do the meets
                self._footprints.clear()
                self._fid.clear()
                self._meets.clear()
            shape = (
                v.top,
                v.left,
                v.near.shape,
                v.near.tobytes(),
                v.rows.tobytes(),
                v.cols.tobytes(),
            )
            hit = self._fid[id(v)] = (v, self._footprints.setdefault(shape, len(self._footprints)))
        return hit[1]

    def pixels(self, v: TopView, pr: int, pc: int) -> tuple[np.ndarray, np.ndarray]:
        """Flat pixel indices (N,) of view v at pixel (pr, pc) inside the frame, and their
        colours (N,) PIXEL."""
        n, half = self.size_px, self.size_px // 2
        hit = self._flat.get(id(v))
        if hit is None or hit[0] is not v:
            if len(self._flat) >= MEMO:
                self._flat.clear()
            rows, cols = v.rows.astype(np.intp), v.cols.astype(np.intp)
            box = (rows.min(), rows.max(), cols.min(), cols.max()) if len(rows) else (0, 0, 0, 0)
            hit = self._flat[id(v)] = (v, rows * n + cols, box, v.colours.reshape(-1).view(PIXEL))
        _, offsets, (r0, r1, c0, c1), colours = hit
        r, c = pr + half, pc + half
        if r + r0 >= 0 and r + r1 < n and c + c0 >= 0 and c + c1 < n:  # wholly inside
            return offsets + (r * n + c), colours
        rows, cols = v.rows.astype(np.intp) + r, v.cols.astype(np.intp) + c
        inside = (rows >= 0) & (rows < n) & (cols >= 0) & (cols < n)
        return rows[inside] * n + cols[inside], colours[inside]
