"""Top views kept on disk between runs: one .npz (no pickle) per model and renderer.

A view is the same pixels each time the same model is drawn by the same renderer, so a run
need not draw again what an earlier one drew. The file's name is a digest of the compiled
model and MuJoCo's version. Inside, every view carries a digest of its key and arrays, checked
when it is read: a view whose digest does not match (a damaged file) is not taken, and drawn
again when it is needed. The file also names the renderer that drew it (a digest of a few
fixed views as that renderer draws them, `fingerprint`): a renderer that draws them otherwise
(another GL driver, say) takes none of its views.

Processes that share the cache add to the file rather than write it over: `save` reads the
views on disk under an advisory lock beside the file (`<name>.lock`), keeps those the same
renderer drew, adds its own and writes the whole atomically (sim.core.files), so a reader sees
one writer's whole file and concurrent writers lose none of each other's views.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import zipfile
import zlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.core import files
from sim.tabletop.top_view import Key, TopView

_DIGEST_BYTES = 16
# what reading a damaged or foreign file may raise
_UNREADABLE = (
    OSError,
    EOFError,
    KeyError,
    IndexError,
    TypeError,
    ValueError,
    MemoryError,
    NotImplementedError,
    zipfile.BadZipFile,
    zlib.error,
)
_DTYPES = (np.dtype(np.int16), np.dtype(np.int16), np.dtype(np.uint8), np.dtype(bool))


@dataclass(frozen=True)
class Stored:
    """What a store file holds for a renderer: the views it may take, and `problem`, one line
    saying how many views were dropped and why (None when none were, or there is no file)."""

    views: dict[Key, TopView] = field(default_factory=dict)
    problem: str | None = None


def store_path(table, size_px: int) -> Path:
    """Where the views of `table` (sim.tabletop.model.Table) at `size_px` are kept: named by
    its model as compiled, whatever scene it holds now."""
    return files.cache_dir() / "tabletop-views" / f"{size_px}px-{table.digest}.npz"


def view_digest(key: Key, view: TopView) -> bytes:
    """16 bytes of blake2b over a view's key, box and arrays (rows, cols, colours, near)."""
    h = hashlib.blake2b(digest_size=_DIGEST_BYTES)
    h.update(f"{key[0]}\t{key[1]}\t{len(view.rows)}\t{view.top}\t{view.left}\t".encode())
    h.update(f"{view.near.shape}\n".encode())
    for a, dtype in zip((view.rows, view.cols, view.colours, view.near), _DTYPES, strict=True):
        h.update(np.ascontiguousarray(a, dtype).tobytes())
    return h.digest()


def fingerprint(views: Mapping[Key, TopView]) -> str:
    """The renderer that drew `views` (the same few each time), as a hex digest."""
    h = hashlib.blake2b(digest_size=_DIGEST_BYTES)
    for k in sorted(views):
        h.update(view_digest(k, views[k]))
    return h.hexdigest()


def save(path: Path, views: Mapping[Key, TopView], *, renderer: str) -> None:
    """Add `views`, drawn by `renderer`, to those in `path` that the same renderer drew and
    whose digests match, and write them all atomically, under the file's lock."""
    with _locked(path):
        merged = read(path, renderer=renderer).views  # damaged or foreign views are left out
        merged.update(views)
        files.write_bytes(path, _encode(merged, renderer))


def read(path: Path, *, renderer: str) -> Stored:
    """The views in `path` that `renderer` drew and whose digests match; the others dropped,
    with one line saying so. No file is no views and no problem."""
    try:
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        n = len(arrays["keys"])
        if "digests" not in arrays or "renderer" not in arrays:
            return Stored(problem=_line(path, "carry no digests (an older format)", n, n))
        stored = _decode(arrays)
    except FileNotFoundError:
        return Stored()
    except _UNREADABLE:
        return Stored(problem=_line(path, "could not be read"))
    if str(arrays["renderer"]) != renderer:
        return Stored(problem=_line(path, "were drawn by another renderer", n, n))
    good = {k: v for k, v, d in stored if view_digest(k, v) == d}
    bad = n - len(good)  # a key stored twice (no file `save` writes) counts as damaged
    return Stored(good, _line(path, "did not match their digests", bad, n) if bad else None)


def _decode(z: Mapping[str, np.ndarray]) -> list[tuple[Key, TopView, bytes]]:
    """(key, view, stored digest) of each view in a store file's arrays; ValueError when they
    do not fit together."""
    keys, counts, boxes, digests = z["keys"], z["counts"], z["boxes"], z["digests"]
    rows, cols, colours, near = z["rows"], z["cols"], z["colours"], z["near"]
    n = len(keys)
    at = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    near_at = np.concatenate([[0], np.cumsum(boxes[:, 2] * boxes[:, 3])]).astype(np.int64)
    if (
        counts.shape != (n,)
        or boxes.shape != (n, 4)
        or digests.shape != (n, _DIGEST_BYTES)
        or (rows.dtype, cols.dtype, colours.dtype, near.dtype) != _DTYPES
        or colours.shape[1:] != (3,)
        or not len(rows) == len(cols) == len(colours) == at[-1]
        or len(near) != near_at[-1]
        or (counts < 0).any()
        or (boxes[:, 2:] < 0).any()
    ):
        raise ValueError("the arrays of a store file do not fit together")
    out = []
    for i, key in enumerate(keys):
        shape, _, colour = str(key).partition("\t")
        top, left, h, w = (int(b) for b in boxes[i])
        view = TopView(
            rows[at[i] : at[i + 1]],
            cols[at[i] : at[i + 1]],
            colours[at[i] : at[i + 1]],
            top,
            left,
            near[near_at[i] : near_at[i + 1]].reshape(h, w),
        )
        out.append(((shape, colour), view, digests[i].tobytes()))
    return out


def _line(path: Path, why: str, dropped: int | None = None, n: int | None = None) -> str:
    """One line: how many of the views in `path` were dropped (all, when not counted), and
    why."""
    count = "the" if n is None else f"{dropped} of {n}"
    return f"{count} cached tabletop views in {path} {why}; they are drawn again"


def _encode(views: Mapping[Key, TopView], renderer: str) -> bytes:
    """The .npz bytes of `views`: the pixels of all views concatenated, with each view's key,
    pixel count, box, grown footprint and digest, and the renderer that drew them."""
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
        digests=np.frombuffer(b"".join(view_digest(k, views[k]) for k in keys), np.uint8).reshape(
            -1, _DIGEST_BYTES
        ),
        renderer=np.array(renderer),
    )
    return buf.getvalue()


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """Hold an exclusive advisory lock on `<path>.lock` (created beside it) for the block;
    where the file system refuses locks, the block runs unlocked (writes stay atomic, only
    views another process adds at the same moment may be lost)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_name(path.name + ".lock"), "ab") as lock:
        with contextlib.suppress(OSError):
            fcntl.flock(lock.fileno(), fcntl.LOCK_EX)
        yield  # closing the file lets the lock go
