"""Top views kept on disk between runs: one .npz (no pickle) per model and renderer.

A view is the same pixels each time the same model is drawn by the same renderer, so a run
need not draw again what an earlier one drew. The file's name is a digest of the compiled
model and MuJoCo's version; the compositor also draws a few stored views again when it opens a
file and drops the file when they differ (another GL driver, say).
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from sim.core import files
from sim.tabletop.top_view import Key, TopView


def store_path(table, size_px: int) -> Path:
    """Where the views of `table` (sim.tabletop.model.Table) at `size_px` are kept: named by
    its model as compiled, whatever scene it holds now."""
    return files.cache_dir() / "tabletop-views" / f"{size_px}px-{table.digest}.npz"


def save(path: Path, views: Mapping[Key, TopView]) -> None:
    """Write `views` to `path` atomically: the pixels of all views concatenated, with each
    view's key, pixel count, box and grown footprint."""
    keys = list(views)
    vs = [views[k] for k in keys]
    buf = io.BytesIO()
    np.savez(
        buf,
        keys=np.array([f"{s}\t{c}" for s, c in keys]),
        counts=np.array([len(v.rows) for v in vs], np.int64),
        rows=np.concatenate([v.rows for v in vs]) if vs else np.zeros(0, np.int16),
        cols=np.concatenate([v.cols for v in vs]) if vs else np.zeros(0, np.int16),
        colours=np.concatenate([v.colours for v in vs]) if vs else np.zeros((0, 3), np.uint8),
        boxes=np.array([(v.top, v.left, *v.near.shape) for v in vs], np.int64).reshape(-1, 4),
        near=np.concatenate([v.near.ravel() for v in vs]) if vs else np.zeros(0, bool),
    )
    files.write_bytes(path, buf.getvalue())


def load(path: Path) -> dict[Key, TopView]:
    """The views in `path`; empty when there is no file or it cannot be read as one."""
    try:
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            keys, counts, boxes = z["keys"], z["counts"], z["boxes"]
            rows, cols, colours, near = z["rows"], z["cols"], z["colours"], z["near"]
    except (OSError, EOFError, KeyError, TypeError, ValueError, zipfile.BadZipFile):
        return {}
    out: dict[Key, TopView] = {}
    at = np.concatenate([[0], np.cumsum(counts)])
    sizes = boxes[:, 2] * boxes[:, 3]
    near_at = np.concatenate([[0], np.cumsum(sizes)])
    if len(rows) != at[-1] or len(near) != near_at[-1] or len(keys) != len(boxes):
        return {}
    for i, key in enumerate(keys):
        shape, _, colour = str(key).partition("\t")
        top, left, h, w = (int(b) for b in boxes[i])
        out[(shape, colour)] = TopView(
            rows[at[i] : at[i + 1]],
            cols[at[i] : at[i + 1]],
            colours[at[i] : at[i + 1]],
            top,
            left,
            near[near_at[i] : near_at[i + 1]].reshape(h, w),
        )
    return out
