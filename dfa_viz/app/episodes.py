"""The episodes of a LeRobotDataset the page offers as demonstrations (`dfa serve --demos DIR`).

The folder is named on the command line, never by the browser, and read once before the page is
served (one that is not a dataset with frames and actions is one line): per episode its first
scene (the `dfa.scene` column of a dataset dfa wrote), its role and whether it succeeds, from the
data tables' columns alone; no frame is decoded until an episode is used. For a task the page
offers the episodes that start from the task's scene; a dataset that names no scenes (anyone's)
offers all of its episodes. The chosen one is checked and replayed by sim.lerobot.demo, as
`dfa run --demo lerobot:DIR:episode=N` does: one whose frames are not the task's is refused in one
line naming the first step that differs.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from sim.core import Scene, Task, Trajectory, UserError, World
from sim.lerobot import Dataset
from sim.lerobot import format as F
from sim.lerobot.demo import SCENE, DemoSpec, demonstration

ROLE = "dfa.role"  # what a trajectory was in the run dfa exported (demonstration, failed, ...)
INDEXES = ("episode_index", "frame_index")


@dataclass(frozen=True)
class Entry:
    """One episode as the page offers it."""

    index: int
    label: str
    """What the dropdown shows: "episode 0 · demonstration · succeeds · 20 steps"."""
    scene: Scene | None
    """The scene it starts from, where the dataset names its scenes."""


class DemoEpisodes:
    """A dataset's episodes, read once; `offered(task)` the ones the page offers for a task."""

    def __init__(self, root: Path) -> None:
        ds = Dataset(root)
        ds.camera()  # a dataset without frames: its one line
        if F.ACTION not in ds.features:
            raise UserError(f"{root}: no {F.ACTION} feature, so no episode can be replayed")
        if not len(ds):
            raise UserError(f"{root}: no episodes")
        self.root = Path(root)
        self.names_scenes = SCENE in ds.features
        self.entries = _entries(ds, names_scenes=self.names_scenes)
        self._offered: dict[Scene, tuple[Entry, ...]] = {}

    def offered(self, task: Task) -> tuple[Entry, ...]:
        """The episodes that start from the task's scene (all, for a dataset without scenes)."""
        if not self.names_scenes:
            return self.entries
        if task.scene not in self._offered:
            self._offered[task.scene] = tuple(e for e in self.entries if e.scene == task.scene)
        return self._offered[task.scene]

    def describe(self, task: Task) -> str:
        """One line on what is offered for the task, and why."""
        n, name = len(self.entries), f"`{self.root.name}`"
        if not self.names_scenes:
            return (
                f"{name} names no scenes: all {n} episodes are offered, and one whose frames "
                "are not this task's is refused."
            )
        k = len(self.offered(task))
        if not k:
            return f"None of the {n} episodes of {name} starts from this task's scene."
        return f"{k} of the {n} episodes of {name} start from this task's scene."

    def check(self, task: Task, index: object) -> Entry:
        """The offered episode `index`; else a UserError saying what is offered."""
        offered = self.offered(task)
        if isinstance(index, int) and not isinstance(index, bool):
            for entry in offered:
                if entry.index == index:
                    return entry
        listed = ", ".join(str(e.index) for e in offered[:8]) + (", …" if len(offered) > 8 else "")
        why = f"offered: {listed}" if offered else "none starts from this task's scene"
        raise UserError(f"episode {index!r} of {self.root} is not offered for this task; {why}")

    def chosen(
        self, world: World, task: Task, index: object
    ) -> tuple[str, Callable[[], Trajectory]]:
        """(the demonstration's source, what makes it): checked as offered now, replayed by
        sim.lerobot.demo when made."""
        entry = self.check(task, index)
        spec = DemoSpec(self.root, entry.index)
        return spec.source, lambda: demonstration(world, task, spec)


def open_demos(root: Path | None) -> DemoEpisodes | None:
    """`--demos DIR` read (a UserError in one line for a folder that is not a usable dataset)."""
    return None if root is None else DemoEpisodes(root)


def chosen(
    demos: DemoEpisodes | None, world: World, task: Task, index: object
) -> tuple[str, Callable[[], Trajectory]]:
    """DemoEpisodes.chosen, or a UserError when the page was served without a dataset."""
    if demos is None:
        raise UserError("no dataset to take an episode from: dfa serve --demos DIR offers one")
    return demos.chosen(world, task, index)


def _entries(ds: Dataset, *, names_scenes: bool) -> tuple[Entry, ...]:
    firsts: dict[int, dict] = {}
    succeeded: set[int] = set()
    files = sorted({(int(r["data/chunk_index"]), int(r["data/file_index"])) for r in ds.episodes})
    for chunk, file in files:
        path = ds.root / ds.info.get("data_path", F.DATA_PATH).format(
            chunk_index=chunk, file_index=file
        )
        first, wins = _read_firsts(path)
        firsts.update(first)
        succeeded |= wins
    entries = []
    for meta in ds.episodes:
        i = int(meta["episode_index"])
        row = firsts.get(i)
        if row is None:
            raise UserError(f"{ds.root}: episode {i} has no first frame in its data file")
        scene = _scene(row.get(SCENE)) if names_scenes else None
        parts = [f"episode {i}"]
        if row.get(ROLE):
            parts.append(str(row[ROLE]))
        if F.SUCCESS in ds.features:
            parts.append("succeeds" if i in succeeded else "fails")
        parts.append(f"{int(meta['length'])} steps")
        entries.append(Entry(i, " · ".join(parts), scene))
    return tuple(entries)


def _read_firsts(path: Path) -> tuple[dict[int, dict], set[int]]:
    """Per episode in one data file, its first frame's indexes, scene and role; and the
    episodes with a frame of next.success."""
    try:
        have = set(pq.read_schema(path).names)
        if not set(INDEXES) <= have:
            raise UserError(f"{path}: no {' or '.join(INDEXES)} column")
        wanted = [*INDEXES, *(c for c in (SCENE, ROLE, F.SUCCESS) if c in have)]
        table = pq.read_table(path, columns=wanted)
        keep = [c for c in wanted if c != F.SUCCESS]
        first = table.filter(pc.equal(table["frame_index"], 0)).select(keep)
        wins: set[int] = set()
        if F.SUCCESS in have and pa.types.is_boolean(table.schema.field(F.SUCCESS).type):
            won = table.filter(pc.fill_null(table[F.SUCCESS], False))
            wins = set(won["episode_index"].to_pylist())
    except FileNotFoundError:
        raise UserError(f"{path}: missing (the dataset's episode table names it)") from None
    except (OSError, pa.ArrowException) as e:
        raise UserError(f"{path}: cannot read it ({e})") from None
    return {int(r["episode_index"]): r for r in first.to_pylist()}, wins


def _scene(text: object) -> Scene | None:
    """A first frame's scene; None where it is not one (such an episode is never offered)."""
    try:
        return Scene.from_dict(json.loads(str(text)))
    except (ValueError, TypeError, KeyError, AssertionError, UserError):
        return None
