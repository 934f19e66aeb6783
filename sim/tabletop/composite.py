"""Tabletop frames composited from cached top views, exact where a scene allows it.

The camera is orthographic and looks straight down, with shadows, reflections and fog off and
one headlight: an object's pixels depend on its shape, its appearance and where it stands, and
on nothing else in the scene. So a frame whose objects stand apart is the bare table with each
object's top view pasted on it. Two facts make the cache small:

- every slot has the same meshes and materials, so a top view belongs to (shape, appearance),
  not to a slot;
- at 100 px per metre, an upright object moved by a whole number of pixels (every area centre:
  0.23 m = 23 px) is drawn by the same pixels moved by the same amount, so one view serves every
  upright pose on the pixel grid.

A view is drawn once by MuJoCo, four at a time (one per quadrant of a frame, each slot holding
one), and kept in a cache bounded in bytes, least recently used out first, and on disk
(sim.tabletop.view_store) for the next run. A scene is composited
when every present object stands upright on the pixel grid and no two footprints, each grown by
one pixel, meet: then no pixel mixes two objects (the anti-aliased edge of a view is its mix
with the table, which the table frame reproduces) and the frame is MuJoCo's own, pixel for
pixel. Objects whose grown footprints meet (overlapping, or a distractor added where the
object stands) are a group: MuJoCo draws the group alone, where it stands, once, and it is
pasted like one view (a group's pixels mix only with the table and with each other). A scene
with an object off the grid (stacked, tilted, carried) is drawn whole by MuJoCo, through the
same `draw`.
"""

from __future__ import annotations

import sys
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from sim.core import Obj, Scene
from sim.tabletop.tasks import AREAS, VIEW_HALF_M, WORLD, pose
from sim.tabletop.top_view import PIXEL, Key, TopView, ViewIndex, grid_pixel, grow

SLOTS = ("object", "goal", "distractor0", "distractor1")
QUADRANTS = ("top-left", "top-right", "bottom-left", "bottom-right")  # one slot each
CACHE_BYTES = 32 * 2**20  # all 29 x 81 views of the default appearances: about 3 MiB
Draw = Callable[[Sequence[Scene]], np.ndarray]  # scenes -> uint8 (B, H, W, 3), MuJoCo's
Group = tuple[tuple[Key, tuple[int, int]], ...]  # touching objects' (view, pixel), slot order
GROUP_VIEWS = 4096  # views of touching groups kept (a few KiB each), least recently used out
# one frame of views that names the renderer of a store file: thin strokes, curves, textures and
# a large goal's rim, where another GL driver draws some pixel otherwise
PROBE: tuple[Key, ...] = (
    ("letter R", "tiger"),
    ("star", "rainbow"),
    ("heart", "dark purple"),
    ("frame", "checkerboard"),
)


class Compositor:
    """Frames of tabletop scenes from cached top views, MuJoCo (`draw`) where not exact.

    draw: MuJoCo's batched render (TopCamera.render_batch); like: a scene whose absent objects'
    values say how the four slots are named and valued; cache_bytes: the views' bound.
    """

    def __init__(
        self,
        draw: Draw,
        like: Scene,
        *,
        size_px: int = 80,
        view_half_m: float = VIEW_HALF_M,
        cache_bytes: int = CACHE_BYTES,
        store: Path | None = None,
    ) -> None:
        self.draw = draw
        self.store = store
        self.size_px = size_px
        self.px_per_m = size_px / (2 * view_half_m)
        self.cache_bytes = cache_bytes
        self.views: OrderedDict[Key, TopView] = OrderedDict()
        self.bytes = 0
        self.drawn = 0  # views drawn so far (for benchmarks)
        self.fell_back = 0  # scenes handed to MuJoCo whole so far (for benchmarks)
        self.groups: OrderedDict[Group, TopView] = OrderedDict()  # not kept on disk
        self.groups_drawn = 0  # groups of touching objects drawn so far (for benchmarks)
        self.index = ViewIndex(size_px)
        self._empty = Scene(
            WORLD, tuple(Obj(s, False, like.obj(s).values, like.obj(s).pos) for s in SLOTS), (0.0,)
        )
        self.table = draw([self._empty])[0]  # (H, W, 3) uint8: the bare table
        self.renderer: str | None = None  # view_store.fingerprint of PROBE, with a store
        if store is not None:
            self._open(store)

    # -- the cache -----------------------------------------------------------------------------
    def clear(self) -> None:
        self.views.clear()
        self.groups.clear()
        self.index.clear()
        self.bytes = 0

    def reopen(self) -> None:
        """Empty the cache and read the stored views again, as a new process would."""
        self.clear()
        self.renderer = None  # named again from a fresh drawing, as a new process names it
        if self.store is not None:
            self._open(self.store)

    def _open(self, store: Path) -> None:
        """Take the views kept in `store` (sim.tabletop.view_store) that this renderer drew
        (the file names the renderer by how it draws `PROBE`, drawn here once) and whose
        digests match; print one line to stderr when any are dropped (they are drawn again)."""
        from sim.tabletop import view_store

        if self.renderer is None:
            self.store = None  # drawing the probe must not write the file before it is read
            try:
                self.renderer = view_store.fingerprint(self.top_views(PROBE))
            finally:
                self.store = store
        stored = view_store.read(store, renderer=self.renderer)
        if stored.problem is not None:
            print(f"dfa: {stored.problem}", file=sys.stderr)
        for k, v in stored.views.items():
            if k not in self.views:
                self._keep(k, v)

    def _keep(self, key: Key, view: TopView) -> None:
        self.views[key] = view
        self.bytes += view.nbytes
        while self.bytes > self.cache_bytes and len(self.views) > 1:
            _, old = self.views.popitem(last=False)
            self.bytes -= old.nbytes

    def top_views(self, keys: Sequence[Key]) -> dict[Key, TopView]:
        """The views of `keys`, drawing the missing ones (four per MuJoCo frame)."""
        got, missing = _known(self.views, keys)
        frames = [missing[i : i + len(QUADRANTS)] for i in range(0, len(missing), len(QUADRANTS))]
        if frames:
            images = self.draw([self._studio(f, QUADRANTS) for f in frames])  # (F, H, W, 3)
            alone = []
            for keys_f, img in zip(frames, images, strict=True):
                cut = [self._cut(img, a, whole=False) for a in QUADRANTS[: len(keys_f)]]
                whole = [v for v in cut if v is not None]
                if len(whole) < len(cut):  # one may spill into another's quadrant
                    alone += keys_f
                    continue
                got.update(zip(keys_f, whole, strict=True))
            if alone:
                images = self.draw([self._studio([k], ("centre",)) for k in alone])
                for key, img in zip(alone, images, strict=True):
                    view = self._cut(img, "centre", whole=True)
                    assert view is not None, f"{key} fills the whole frame"
                    got[key] = view
            self.drawn += len(missing)
            for k in missing:
                self._keep(k, got[k])
            if self.store is not None:
                from sim.tabletop import view_store

                view_store.save(self.store, self.views, renderer=self.renderer)
        return got

    def _studio(self, keys: Sequence[Key], areas: Sequence[str]) -> Scene:
        """A scene with one object per key, slot by slot, at the areas' centres."""
        objs = list(self._empty.objects)
        for i, ((shape, colour), area) in enumerate(zip(keys, areas, strict=False)):
            objs[i] = Obj(SLOTS[i], True, (("shape", shape), ("colour", colour)), pose(area))
        return Scene(WORLD, tuple(objs), (0.0,))

    def _cut(
        self, img: np.ndarray, area: str, *, whole: bool, clipped: bool = False
    ) -> TopView | None:
        """The view of the object at `area`'s centre: the pixels of its frame quadrant (the
        whole frame when `whole`) that differ from the table; None when they reach an edge of
        that window (the object may spill out of it), unless `clipped` (a view that holds
        only where it was drawn)."""
        n, half = self.size_px, self.size_px // 2
        x, y = AREAS[area]
        r0, c0 = half + round(-y * self.px_per_m), half + round(x * self.px_per_m)
        rows = (0, n) if whole else ((0, half) if y > 0 else (half, n))
        cols = (0, n) if whole else ((0, half) if x < 0 else (half, n))
        window = (slice(*rows), slice(*cols))
        rr, cc = np.nonzero((img[window] != self.table[window]).any(axis=-1))
        if len(rr) == 0:  # nothing drawn: an empty view
            top = bottom = rows[0] + 1
            left = right = cols[0] + 1
        else:
            top, bottom = rows[0] + rr.min(), rows[0] + rr.max() + 1
            left, right = cols[0] + cc.min(), cols[0] + cc.max() + 1
        edge = top == rows[0] or bottom == rows[1] or left == cols[0] or right == cols[1]
        if edge and not clipped:
            return None
        crop = (slice(top, bottom), slice(left, right))
        mask = (img[crop] != self.table[crop]).any(axis=-1)  # (h, w)
        rr, cc = np.nonzero(mask)
        return TopView(
            (rr + top - r0).astype(np.int16),
            (cc + left - c0).astype(np.int16),
            img[crop][mask],  # (N, 3)
            int(top - r0 - 1),
            int(left - c0 - 1),
            grow(mask),
        )

    # -- frames --------------------------------------------------------------------------------
    def _placement(
        self, scene: Scene, memo: dict
    ) -> list[tuple[Key, tuple[int, int]] | None] | None:
        """Per slot the (view key, pixel) of its object, None where absent; None for the whole
        scene when an object is off the grid. memo: id(Obj) -> its entry, for one batch (an
        edit leaves the other objects of a scene the same objects)."""
        objs = []
        for o in scene.objects:
            hit = memo.get(id(o))
            if hit is None:
                if not o.present:
                    hit = (None,)
                else:
                    p = grid_pixel(o, self.px_per_m)
                    hit = (None if p is None else ((o.value("shape"), o.value("colour")), p), o)
                memo[id(o)] = hit
            if o.present and hit[0] is None:
                return None
            objs.append(hit[0])
        return objs

    def _clash(self, objs: Sequence, views: dict[Key, TopView]) -> bool:
        """Whether two of a scene's objects (placements) come within a pixel of each other."""
        shown = [ko for ko in objs if ko is not None]
        return any(
            self.index.meet(views[a], pa, views[b], pb)
            for j, (a, pa) in enumerate(shown)
            for b, pb in shown[j + 1 :]
        )

    def _touching(self, objs: Sequence, views: dict[Key, TopView]) -> list[tuple[int, ...]]:
        """The slots of each group of two or more objects that come within a pixel of each
        other, directly or through others of the group (slot order); [] when none do."""
        shown = [k for k, ko in enumerate(objs) if ko is not None]
        group = {k: k for k in shown}  # slot -> the first slot of its group
        for j, a in enumerate(shown):
            for b in shown[j + 1 :]:
                (ka, pa), (kb, pb) = objs[a], objs[b]
                if group[b] != group[a] and self.index.meet(views[ka], pa, views[kb], pb):
                    old, new = max(group[a], group[b]), min(group[a], group[b])
                    group = {k: new if g == old else g for k, g in group.items()}
        out: dict[int, list[int]] = {}
        for k in shown:
            out.setdefault(group[k], []).append(k)
        return [tuple(g) for g in out.values() if len(g) > 1]

    def group_views(self, groups: Sequence[Group]) -> dict[Group, TopView]:
        """The views of groups of touching objects, each as MuJoCo draws the group alone where
        it stands (relative to the frame's centre), drawing the missing ones."""
        got, missing = _known(self.groups, groups)
        if missing:
            images = self.draw([self._alone(g) for g in missing])  # (G, H, W, 3)
            for g, img in zip(missing, images, strict=True):
                got[g] = self.groups[g] = self._cut(img, "centre", whole=True, clipped=True)
            while len(self.groups) > GROUP_VIEWS:
                self.groups.popitem(last=False)
            self.groups_drawn += len(missing)
        return got

    def _alone(self, group: Group) -> Scene:
        """A scene of the group's objects where they stand, one per slot in the group's order
        (every slot has the same meshes and materials, drawn in slot order)."""
        objs = list(self._empty.objects)
        for i, ((shape, colour), (r, c)) in enumerate(group):
            xy = (c / self.px_per_m, -r / self.px_per_m)
            objs[i] = Obj(SLOTS[i], True, (("shape", shape), ("colour", colour)), pose(xy))
        return Scene(WORLD, tuple(objs), (0.0,))

    def render_batch(self, scenes: Sequence[Scene]) -> np.ndarray:
        """uint8 (B, H, W, 3): the same pixels as `draw(scenes)`.

        Every frame starts as one base frame (the table with each slot's most common object of
        the batch), then, slot by slot where a scene differs from the base, the base object is
        wiped back to the table and the scene's own is pasted: a batch of edits of one scene
        touches only the pixels its edits change. Objects that come within a pixel of each
        other are pasted as one group, which MuJoCo draws alone the first time it is met.
        """
        n = self.size_px
        memo: dict = {}
        placed = [self._placement(s, memo) for s in scenes]
        views = self.top_views([ko[0] for objs in placed if objs for ko in objs if ko is not None])
        whole = [i for i, objs in enumerate(placed) if objs is None]  # off the grid
        touching: dict[int, list[tuple[int, ...]]] = {}
        for i, objs in enumerate(placed):
            if objs is not None and self._clash(objs, views):
                touching[i] = self._touching(objs, views)
        grouped = self.group_views(
            [tuple(placed[i][k] for k in g) for i, gs in touching.items() for g in gs]
        )
        ok = [objs for objs in placed if objs is not None]
        base: list = [None] * len(SLOTS)
        if ok:
            for k in range(len(SLOTS)):
                counts: dict = {}
                for objs in ok:
                    counts[objs[k]] = counts.get(objs[k], 0) + 1
                base[k] = max(counts, key=counts.get)  # ties: the first seen
            if self._clash(base, views):  # the commonest objects meet: start from the table
                base = [None] * len(SLOTS)
        frame = self.table.copy()
        flat_frame = frame.reshape(n * n * 3).view(PIXEL)  # (H * W,)
        for ko in base:
            if ko is not None:
                idx, vals = self.index.pixels(views[ko[0]], *ko[1])
                flat_frame[idx] = vals
        out = np.empty((len(scenes), n, n, 3), np.uint8)
        out[:] = frame
        wipes: dict[int, list[int]] = {}  # slot -> scenes whose slot differs from the base's
        pastes: dict[tuple[Key, tuple[int, int]], list[int]] = {}  # (view, pixel) -> scenes
        group_pastes: dict[Group, list[int]] = {}  # group -> scenes
        skip = set(whole)
        covered = [self._covers(views, b) for b in base]
        for i, objs in enumerate(placed):
            if i in skip:
                continue
            members = set()
            for g in touching.get(i, ()):
                members.update(g)
                group_pastes.setdefault(tuple(objs[k] for k in g), []).append(i)
            for k, ko in enumerate(objs):
                if ko != base[k] or k in members:
                    if base[k] is not None and (k in members or not covered[k](ko)):
                        wipes.setdefault(k, []).append(i)
                    if ko is not None and k not in members:
                        pastes.setdefault(ko, []).append(i)
        flat = out.reshape(len(scenes), n * n * 3).view(PIXEL)  # (B, H * W)
        table = self.table.reshape(n * n * 3).view(PIXEL)  # (H * W,)
        for k, rows in wipes.items():  # every wipe before any paste: a new object may stand
            idx, _ = self.index.pixels(views[base[k][0]], *base[k][1])  # where a base one stood
            _scatter(flat, rows, idx, table[idx])
        for ko, rows in pastes.items():
            _scatter(flat, rows, *self.index.pixels(views[ko[0]], *ko[1]))
        for g, rows in group_pastes.items():
            _scatter(flat, rows, *self.index.pixels(grouped[g], 0, 0))
        if whole:
            self.fell_back += len(whole)
            out[whole] = self.draw([scenes[i] for i in whole])
        return out

    def _covers(self, views: dict[Key, TopView], base) -> Callable[[object], bool]:
        """Whether a placement's pixels are exactly the base placement's (the same footprint
        at the same pixel): pasting it then overwrites every pixel of the base's, and the
        base need not be wiped first."""
        if base is None:
            return lambda ko: False
        mine = self.index.footprint(views[base[0]])
        memo: dict = {}

        def covers(ko) -> bool:
            if ko is None or ko[1] != base[1]:
                return False
            hit = memo.get(ko[0])
            if hit is None:
                hit = memo[ko[0]] = self.index.footprint(views[ko[0]]) == mine
            return hit

        return covers


def _known(cache: OrderedDict, keys: Sequence) -> tuple[dict, list]:
    """({key: view} of the distinct keys the LRU `cache` holds, now its most recent; the
    distinct keys it lacks, in order)."""
    got, missing = {}, []
    for k in dict.fromkeys(keys):
        v = cache.get(k)
        if v is None:
            missing.append(k)
        else:
            cache.move_to_end(k)
            got[k] = v
    return got, missing


def _scatter(flat: np.ndarray, rows: list[int], idx: np.ndarray, vals: np.ndarray) -> None:
    """flat[r, idx] = vals for every r in rows; flat (B, P) and vals (N,) PIXEL, idx (N,)."""
    if len(rows) == 1:
        np.put(flat[rows[0]], idx, vals)  # a third of a fancy assignment's time
    else:
        flat[np.asarray(rows)[:, None], idx[None, :]] = vals[None]
