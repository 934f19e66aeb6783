"""The sweep's pictures (matplotlib's Agg canvas, no pyplot state): the heatmap of each edit's
difference from the control arm (slot.concept x value), which also says which cell a point of
it shows, and a bar chart per concept for the recording.

The heatmap has one panel per set of values (e.g. the colours; the shapes; present/absent),
a row per slot.concept that takes them: each cell the failure rate of that edit minus the
failure rate of the same tasks unedited (red: the edit breaks the policy; blue: it helps),
grey where it never applies (the value every task already has).
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from search.sweep import CellKey, SweepResult
from sim.core import PRESENCE, ConceptSpace

LEFT_IN = 1.7  # row labels
RIGHT_IN = 1.0  # the colour bar
ROW_IN = 0.3  # one row
CELL_IN = (0.09, 0.6)  # a column's width: at least, at most
PANEL_WIDTH_IN = 6.8  # a panel's widest
TITLE_IN = 0.3
DPI = 100
NAMED_COLUMNS = 40  # panels with more values label every few only
ANNOTATED_COLUMNS = 12  # panels with at most this many values print each cell's rate
NOT_APPLIED = (0.82, 0.82, 0.82)


@dataclass(frozen=True)
class Panel:
    """One panel of the heatmap: its cells' box in image pixels (x0, y0, x1, y1; y down)."""

    box: tuple[float, float, float, float]
    rows: tuple[tuple[str, str], ...]
    """(slot, concept) per row, top first."""
    values: tuple[str, ...]


@dataclass(frozen=True)
class Heatmap:
    """The heatmap as an image, and where each cell of it lies."""

    image: np.ndarray  # (H, W, 3) uint8
    panels: tuple[Panel, ...]

    def cell_at(self, u: float, v: float) -> CellKey | None:
        """The cell under a point of the image (u, v in [0, 1], v down), or None."""
        h, w = self.image.shape[:2]
        x, y = u * w, v * h
        for p in self.panels:
            x0, y0, x1, y1 = p.box
            if x0 <= x < x1 and y0 <= y < y1:
                row = int((y - y0) / (y1 - y0) * len(p.rows))
                col = int((x - x0) / (x1 - x0) * len(p.values))
                slot, concept = p.rows[min(row, len(p.rows) - 1)]
                return (slot, concept, p.values[min(col, len(p.values) - 1)])
        return None

    def centre(self, key: CellKey) -> tuple[float, float]:
        """(u, v) of a cell's centre: where to point at it."""
        h, w = self.image.shape[:2]
        for p in self.panels:
            if key[:2] in p.rows and key[2] in p.values:
                x0, y0, x1, y1 = p.box
                r, c = p.rows.index(key[:2]), p.values.index(key[2])
                x = x0 + (c + 0.5) * (x1 - x0) / len(p.values)
                y = y0 + (r + 0.5) * (y1 - y0) / len(p.rows)
                return x / w, y / h
        raise KeyError(key)


def groups(space: ConceptSpace) -> list[tuple[str, tuple[str, ...], list[tuple[str, str]]]]:
    """(concept name, values, [(slot, concept), ...]): the heatmap's panels, presence first,
    in the concept space's order."""
    out: dict[tuple[str, tuple[str, ...]], list[tuple[str, str]]] = {}
    for s in space.slots:
        if s.optional:
            out.setdefault((PRESENCE, space.values(s.name, PRESENCE)), []).append(
                (s.name, PRESENCE)
            )
    for s in space.slots:
        for c in s.concepts:
            out.setdefault((c.name, tuple(c.values)), []).append((s.name, c.name))
    return [(name, values, rows) for (name, values), rows in out.items()]


def heatmap(space: ConceptSpace, result: SweepResult) -> Heatmap:
    """The difference from the control of every cell, a panel per set of values (laid out in
    inches, so that each cell's place in the image is known exactly)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels = []
    for name, values, rows in groups(space):
        cell = min(CELL_IN[1], max(CELL_IN[0], PANEL_WIDTH_IN / len(values)))
        step = 1 if len(values) <= NAMED_COLUMNS else math.ceil(len(values) / NAMED_COLUMNS)
        ticks = list(range(0, len(values), step))
        labels_in = 0.2 + 0.07 * max(len(values[k]) for k in ticks)
        panels.append((name, values, rows, cell * len(values), ticks, labels_in))
    width = max(5.5, LEFT_IN + max(p[3] for p in panels) + RIGHT_IN)
    height = 3 * TITLE_IN + 0.2 + sum(TITLE_IN + len(p[2]) * ROW_IN + p[5] for p in panels)
    fig = Figure(figsize=(width, height), dpi=DPI)
    canvas = FigureCanvasAgg(fig)
    rates = {c.key: c.difference for c in result.cells if not c.is_pair}
    cmap = _cmap()
    top = height - 3 * TITLE_IN - 0.2
    axes = []
    image = None
    for name, values, rows, w, ticks, labels_in in panels:
        h = len(rows) * ROW_IN
        top -= TITLE_IN
        ax = fig.add_axes((LEFT_IN / width, (top - h) / height, w / width, h / height))
        top -= h + labels_in
        grid = np.array(
            [[rates.get((s, c, v), math.nan) for v in values] for s, c in rows], np.float64
        )  # (rows, values)
        image = ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=-1, vmax=1, aspect="auto")
        ax.set_yticks(range(len(rows)), [f"{s}.{c}" for s, c in rows], fontsize=8)
        ax.set_xticks(ticks, [values[k] for k in ticks], fontsize=7, rotation=90)
        ax.set_title(f"{name} ({len(values)} values)", fontsize=9, loc="left")
        if len(values) <= ANNOTATED_COLUMNS:
            for r, k in np.ndindex(grid.shape):
                if grid[r, k] == grid[r, k]:
                    colour = "white" if abs(grid[r, k]) > 0.6 else "black"
                    ax.text(
                        k,
                        r,
                        f"{100 * grid[r, k]:+.0f}",
                        ha="center",
                        va="center",
                        fontsize=7,
                        color=colour,
                    )
        axes.append((ax, rows, values))
    fig.suptitle(
        f"{result.world} · {result.policy or 'policy'}: each single edit's failure rate\n"
        f"minus the same tasks' unedited (points; {result.distinct} distinct tasks\n"
        f"of {result.tasks}; grey: never applies)",
        fontsize=9,
        x=0.02,
        ha="left",
    )
    if image is not None:
        bar = fig.add_axes(((width - RIGHT_IN + 0.25) / width, 0.1, 0.15 / width, 0.75))
        colour_bar = fig.colorbar(image, cax=bar)
        colour_bar.set_label("Δ failure rate", fontsize=8)
        bar.yaxis.set_label_position("left")
    canvas.draw()
    pixels = np.asarray(canvas.buffer_rgba())[..., :3].copy()  # (H, W, 3) uint8
    h_px = pixels.shape[0]
    boxes = []
    for ax, rows, values in axes:
        b = ax.get_window_extent()  # display pixels, y up
        boxes.append(Panel((b.x0, h_px - b.y1, b.x1, h_px - b.y0), tuple(rows), tuple(values)))
    return Heatmap(pixels, tuple(boxes))


def _cmap():
    from matplotlib import colormaps

    return colormaps["RdBu_r"].with_extremes(bad=NOT_APPLIED)


def png_bytes(image: np.ndarray) -> bytes:
    """uint8 (H, W, 3) as the bytes of a PNG file."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="png")
    return buf.getvalue()


def concept_bars(result: SweepResult, slot: str, concept: str) -> np.ndarray | None:
    """uint8 (H, W, 3): the difference from the control of each value of slot.concept with its
    95% interval (None where no cell of it applied)."""
    cells = [c for c in result.cells if (c.slot, c.concept) == (slot, concept) and c.n]
    if not cells:
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cells.sort(key=lambda c: -c.difference)
    fig = Figure(figsize=(max(4.8, 0.16 * len(cells) + 1.5), 3.0), dpi=DPI)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    x = np.arange(len(cells))
    rates = np.array([c.difference for c in cells])
    lo = np.array([c.difference_ci[0] for c in cells])
    hi = np.array([c.difference_ci[1] for c in cells])
    ax.bar(x, rates, 0.8, color=_cmap()((rates + 1) / 2))
    err = np.maximum(0.0, [rates - lo, hi - rates])  # (2, n); the bounds may round inside
    ax.errorbar(x, rates, err, fmt="none", ecolor="black", lw=0.8)
    ax.set_xticks(x, [c.value for c in cells], rotation=90, fontsize=7)
    ax.set_ylim(-1.05, 1.05)
    ax.axhline(0, color="black", lw=0.6)
    ax.set_ylabel("failure rate - unedited (95% CI)", fontsize=8)
    ax.set_title(f"{slot}.{concept}: every value, most damaging first", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def concept_names(result: SweepResult) -> Sequence[tuple[str, str]]:
    """Every slot.concept with a cell that applied, most damaging concept first."""
    ranked = [(c.slot, c.concept) for c in result.concepts]
    seen = {(c.slot, c.concept) for c in result.cells if c.n}
    return [k for k in dict.fromkeys([*ranked, *sorted(seen)]) if k in seen]
