"""Reading a LeRobotDataset v3.0 folder (ours or anyone's) into Episodes, with pyarrow and PyAV.

Whatever is wrong with a folder (no meta/info.json, another codebase version, a missing file,
an episode that is not there, frames that do not decode) is one line naming the folder.
"""

from __future__ import annotations

import functools
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sim.core.errors import UserError
from sim.lerobot import format as F
from sim.lerobot.episode import Episode


class Dataset:
    """One dataset folder: its info, tasks and episodes' metadata, read when opened; frames
    and columns read per episode."""

    def __init__(self, root: str | Path) -> None:
        self.root = root = Path(root)
        info_path = root / F.INFO_PATH
        if not info_path.is_file():
            what = "no such folder" if not root.exists() else f"no {F.INFO_PATH}"
            raise UserError(f"{root}: not a LeRobot dataset ({what})")
        try:
            self.info: dict[str, Any] = json.loads(info_path.read_text())
            version = self.info["codebase_version"]
            self.fps = int(self.info["fps"])
            self.features: dict[str, dict[str, Any]] = self.info["features"]
        except (ValueError, KeyError, TypeError) as e:
            raise UserError(
                f"{info_path}: not a LeRobot info.json ({type(e).__name__}: {e})"
            ) from None
        if version != F.CODEBASE_VERSION:
            raise UserError(
                f"{root}: a LeRobotDataset {version}; this reads {F.CODEBASE_VERSION} (LeRobot "
                "converts older ones: lerobot.datasets.v30.convert_dataset_v21_to_v30)"
            )
        self.cameras = tuple(
            k for k, f in self.features.items() if f.get("dtype") in ("image", "video")
        )
        self.robot_type: str | None = self.info.get("robot_type")
        self.tasks = F.task_texts(self._table(root / F.TASKS_PATH))
        parts = sorted((root / F.EPISODES_DIR).glob("chunk-*/file-*.parquet"))
        if not parts:
            raise UserError(f"{root}: no episode table under {F.EPISODES_DIR}")
        tables = [self._table(p) for p in parts]
        keep = [c for c in tables[0].column_names if not c.startswith("stats/")]
        rows = pa.concat_tables([t.select(keep) for t in tables]).to_pylist()
        self.episodes: list[dict[str, Any]] = sorted(rows, key=lambda r: r["episode_index"])
        if [r["episode_index"] for r in self.episodes] != list(range(len(self.episodes))):
            raise UserError(f"{root}: episode_index in {F.EPISODES_DIR} is not 0, 1, 2, ...")

    def _table(self, path: Path) -> pa.Table:
        try:
            return pq.read_table(path)
        except (OSError, pa.ArrowException) as e:
            raise UserError(f"{path}: cannot read it ({e})") from None
        except ValueError as e:
            raise UserError(f"{path}: {e}") from None

    def __len__(self) -> int:
        return len(self.episodes)

    @property
    def total_frames(self) -> int:
        return sum(int(r["length"]) for r in self.episodes)

    def camera(self, name: str | None = None) -> str:
        """The image or video feature to read: `name` (a full key or the part after
        observation.images.), else the first."""
        if not self.cameras:
            raise UserError(f"{self.root}: no image or video feature to read frames from")
        if name is None:
            return self.cameras[0]
        for key in self.cameras:
            if name in (key, key.removeprefix(F.IMAGES_PREFIX)):
                return key
        raise UserError(f"{self.root}: no camera {name!r}; it has {', '.join(self.cameras)}")

    def check_index(self, n: int) -> dict[str, Any]:
        if not 0 <= n < len(self.episodes):
            raise UserError(
                f"{self.root}: no episode {n}; it has episodes 0 to {len(self.episodes) - 1}"
            )
        return self.episodes[n]

    @functools.lru_cache(maxsize=1)  # noqa: B019 (one data file at a time: episodes in order)
    def _data(self, chunk: int, file: int) -> pa.Table:
        path = self.root / self.info.get("data_path", F.DATA_PATH).format(
            chunk_index=chunk, file_index=file
        )
        if not path.is_file():
            raise UserError(f"{path}: missing (the dataset's episode table names it)")
        return self._table(path)

    def episode(self, n: int, *, camera: str | None = None) -> Episode:
        """Episode n: its frames of `camera`, actions, task, success and other columns."""
        meta = self.check_index(n)
        key = self.camera(camera)
        table = self._data(int(meta["data/chunk_index"]), int(meta["data/file_index"]))
        idx = np.asarray(table["episode_index"].to_numpy()) == n
        rows = table.filter(pa.array(idx))
        t = rows.num_rows
        if t != int(meta["length"]) or t == 0:
            raise UserError(
                f"{self.root}: episode {n} has {t} frames, its metadata says {meta['length']}"
            )
        order = np.argsort(rows["frame_index"].to_numpy())
        rows = rows.take(pa.array(order))
        if F.ACTION not in rows.column_names:
            raise UserError(f"{self.root}: no action feature")
        frames = self._frames(key, meta, rows)
        own = {*F.DEFAULT_FEATURES, F.ACTION, F.SUCCESS, F.DONE, *self.cameras}
        columns = {name: _numpy(rows[name]) for name in rows.column_names if name not in own}
        names = rows.column_names
        success = F.SUCCESS in names and bool(rows[F.SUCCESS][rows.num_rows - 1].as_py())
        task_index = int(rows["task_index"][0].as_py())
        task = self.tasks[task_index] if 0 <= task_index < len(self.tasks) else ""
        return Episode(task, frames, _numpy(rows[F.ACTION]), success, columns)

    def _frames(self, key: str, meta: dict[str, Any], rows: pa.Table) -> np.ndarray:
        if self.features[key]["dtype"] == "image":
            return np.stack(
                [_decode_png(v["bytes"], self.root, key) for v in rows[key].to_pylist()]
            )
        from sim.lerobot.video import read_frames

        path = self.root / (self.info.get("video_path") or F.VIDEO_PATH).format(
            video_key=key,
            chunk_index=int(meta[f"videos/{key}/chunk_index"]),
            file_index=int(meta[f"videos/{key}/file_index"]),
        )
        if not path.is_file():
            raise UserError(f"{path}: missing (the dataset's episode table names it)")
        start = float(meta[f"videos/{key}/from_timestamp"]) + float(rows["timestamp"][0].as_py())
        return read_frames(path, start, rows.num_rows, self.fps)


def _numpy(column: pa.ChunkedArray) -> np.ndarray:
    """A column as (T,) or (T, n) numpy values; text as an object array."""
    col = column.combine_chunks()
    if pa.types.is_fixed_size_list(col.type) or pa.types.is_list(col.type):
        values = col.flatten().to_numpy(zero_copy_only=False)
        return values.reshape(len(col), -1)
    if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
        return np.array(col.to_pylist(), dtype=object)
    return col.to_numpy(zero_copy_only=False)


def _decode_png(data: bytes, root: Path, key: str) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as im:
            return np.asarray(im.convert("RGB"), dtype=np.uint8)
    except (UnidentifiedImageError, OSError) as e:
        raise UserError(f"{root}: an image of {key} does not decode ({e})") from None
