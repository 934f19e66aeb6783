"""Writing a LeRobotDataset v3.0 folder from episodes (format.py says where each part goes).

The folder is built beside its place under a hidden temporary name and moved into place when
whole: a dataset that was there stays as it was until then (and is replaced), a run cut short
leaves no half dataset. A folder that is not a LeRobotDataset is never replaced.
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sim.core.errors import UserError
from sim.lerobot import format as F
from sim.lerobot import stats as S
from sim.lerobot.episode import Episode

CAMERA = "main"  # the one camera of a dfa world: observation.images.main


@dataclass(frozen=True)
class Written:
    """What write_dataset wrote."""

    root: Path
    episodes: int
    frames: int
    video: bool
    """Frames as AV1 video (else PNG images in the tables)."""
    bytes: int


def features_of(
    first: Episode, *, video: bool, action_names: Sequence[str] = (), camera: str = CAMERA
) -> dict[str, dict[str, Any]]:
    """The dataset's features from its first episode (every episode must match them)."""
    h, w, c = first.frames.shape[1:]
    feats: dict[str, dict[str, Any]] = {
        F.IMAGES_PREFIX + camera: {
            "dtype": "video" if video else "image",
            "shape": (h, w, c),
            "names": list(F.IMAGE_NAMES),
        }
    }
    a = first.actions
    if a.ndim == 1:  # a discrete world: one integer per frame
        feats[F.ACTION] = {"dtype": str(a.dtype), "shape": (1,), "names": None}
    else:
        names = list(action_names) if len(action_names) == a.shape[1] else None
        feats[F.ACTION] = {"dtype": str(a.dtype), "shape": (a.shape[1],), "names": names}
    feats[F.SUCCESS] = {"dtype": "bool", "shape": (1,), "names": None}
    feats[F.DONE] = {"dtype": "bool", "shape": (1,), "names": None}
    for name, values in first.columns.items():
        dtype = "string" if values.dtype.kind in "OUS" else str(values.dtype)
        if dtype not in ("string", *F.NUMERIC):
            raise ValueError(f"column {name}: {values.dtype} is neither text nor a number")
        shape = (1,) if values.ndim == 1 or dtype == "string" else tuple(values.shape[1:])
        feats[name] = {"dtype": dtype, "shape": shape, "names": None}
    return feats | {k: dict(v) for k, v in F.DEFAULT_FEATURES.items()}


def _check(ep: Episode, feats: dict[str, dict[str, Any]], index: int) -> None:
    key = next(k for k in feats if k.startswith(F.IMAGES_PREFIX))
    want = tuple(feats[key]["shape"])
    if ep.frames.shape[1:] != want:
        raise UserError(f"episode {index}: frames {ep.frames.shape[1:]}, the dataset's {want}")
    a = feats[F.ACTION]
    t = len(ep.actions)
    shapes = [(t,), (t, 1)] if a["shape"] == (1,) else [(t, *a["shape"])]
    if ep.actions.shape not in shapes or str(ep.actions.dtype) != a["dtype"]:
        raise UserError(
            f"episode {index}: actions {ep.actions.dtype} {ep.actions.shape}, "
            f"the dataset's {a['dtype']} {a['shape']}"
        )
    ours = {k for k in feats if k not in F.DEFAULT_FEATURES and k != key} - {
        F.ACTION,
        F.SUCCESS,
        F.DONE,
    }
    if set(ep.columns) != ours:
        raise UserError(f"episode {index}: columns {sorted(ep.columns)}, expected {sorted(ours)}")


def png(frame: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(frame).save(buf, format="PNG")
    return buf.getvalue()


def _frame_table(
    ep: Episode, feats: dict, schema: pa.Schema, *, index0: int, episode: int, task: int, fps: int
) -> pa.Table:
    t = ep.length
    cols: dict[str, Any] = {}
    for key, f in feats.items():
        if f["dtype"] == "video":
            continue
        if f["dtype"] == "image":
            cols[key] = [
                {"bytes": png(x), "path": f"frame-{i:06d}.png"} for i, x in enumerate(ep.frames)
            ]
        elif key == F.ACTION:
            one = feats[key]["shape"] == (1,)  # a plain column: (T,) or (T, 1) actions
            cols[key] = ep.actions.reshape(t) if one else list(ep.actions)
        elif key == F.SUCCESS:
            cols[key] = np.arange(t) == t - 1 if ep.success else np.zeros(t, bool)
        elif key == F.DONE:
            cols[key] = np.arange(t) == t - 1
        elif key == "timestamp":
            cols[key] = (np.arange(t) / fps).astype(np.float32)
        elif key == "frame_index":
            cols[key] = np.arange(t, dtype=np.int64)
        elif key == "episode_index":
            cols[key] = np.full(t, episode, np.int64)
        elif key == "index":
            cols[key] = np.arange(index0, index0 + t, dtype=np.int64)
        elif key == "task_index":
            cols[key] = np.full(t, task, np.int64)
        else:
            values = ep.columns[key]
            if f["dtype"] == "string":
                cols[key] = [str(v) for v in values]
            else:
                cols[key] = values.reshape(t) if f["shape"] == (1,) else list(values)
    return pa.table({k: pa.array(v, schema.field(k).type) for k, v in cols.items()}, schema=schema)


def _stats_columns(ep: Episode, table: pa.Table, feats: dict) -> dict[str, Any]:
    """An episode's columns as arrays, for its stats (frames for the image or video feature)."""
    out: dict[str, Any] = {}
    for key, f in feats.items():
        if f["dtype"] in ("image", "video"):
            out[key] = ep.frames
        elif f["dtype"] != "string":
            col = table[key].combine_chunks()
            out[key] = (
                np.asarray(col.flatten()).reshape(len(col), -1)
                if f["shape"] != (1,)
                else col.to_numpy(zero_copy_only=False)
            )
    return out


def _stale(root: Path) -> None:
    """Temporary folders of `root` left by processes of this machine that have ended."""
    pattern = re.compile(rf"\.{re.escape(root.name)}\.(\d+)-[a-z0-9_]+\.tmp")
    if not root.parent.is_dir():
        return
    for entry in root.parent.iterdir():
        m = pattern.fullmatch(entry.name)
        if m and entry.is_dir():
            try:
                os.kill(int(m.group(1)), 0)
            except ProcessLookupError:
                shutil.rmtree(entry, ignore_errors=True)
            except PermissionError:
                pass


def check_out(root: Path) -> None:
    """A dataset may replace an earlier dataset or go into an empty or new folder that can be
    written; anything else is refused in one line, before any work."""
    if root.exists() and not root.is_dir():
        raise UserError(f"{root} is a file; give a folder for the dataset")
    if root.is_dir() and any(root.iterdir()) and not (root / F.INFO_PATH).is_file():
        raise UserError(
            f"{root} holds files and is not a LeRobot dataset (no {F.INFO_PATH}); "
            "give a new or empty folder"
        )
    above = root.parent
    while not above.exists():
        above = above.parent
    if not above.is_dir():
        raise UserError(f"{root}: {above} is a file, so nothing can be written under it")
    if not os.access(above, os.W_OK | os.X_OK):
        raise UserError(f"{root}: {above} cannot be written to")


def write_dataset(
    root: str | Path,
    episodes: Iterable[Episode],
    *,
    fps: int,
    robot_type: str | None,
    video: bool,
    action_names: Sequence[str] = (),
    camera: str = CAMERA,
) -> Written:
    """Write `episodes` as a LeRobotDataset v3.0 at `root` (see the module docstring)."""
    root = Path(root)
    check_out(root)
    if not isinstance(fps, int) or fps < 1:
        raise UserError(f"fps must be a positive whole number, not {fps}")
    root.parent.mkdir(parents=True, exist_ok=True)
    _stale(root)
    tmp = Path(
        tempfile.mkdtemp(dir=root.parent, prefix=f".{root.name}.{os.getpid()}-", suffix=".tmp")
    )
    try:
        written = _write(tmp, episodes, fps, robot_type, video, action_names, camera)
        if root.exists():  # the earlier dataset goes once the new one is whole
            old = Path(
                tempfile.mkdtemp(
                    dir=root.parent, prefix=f".{root.name}.{os.getpid()}-", suffix=".tmp"
                )
            )
            os.replace(root, old / "old")
            os.replace(tmp, root)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return Written(root, written[0], written[1], video, written[2])


def _write(
    tmp: Path, episodes, fps, robot_type, video, action_names, camera
) -> tuple[int, int, int]:
    feats: dict[str, dict[str, Any]] | None = None
    schema: pa.Schema | None = None
    tasks: dict[str, int] = {}
    rows: list[dict[str, Any]] = []
    ep_stats: list[dict] = []
    data_at, data_bytes, writer = (0, 0), 0, None
    vid_at, vid = (0, 0), None
    vkey = F.IMAGES_PREFIX + camera
    frames = 0
    try:
        for i, ep in enumerate(episodes):
            if feats is None:
                feats = features_of(ep, video=video, action_names=action_names, camera=camera)
                schema = F.frame_schema(feats)
            _check(ep, feats, i)
            task = tasks.setdefault(ep.task, len(tasks))
            table = _frame_table(ep, feats, schema, index0=frames, episode=i, task=task, fps=fps)
            if (
                writer is not None
                and data_bytes + table.nbytes >= F.DATA_FILES_SIZE_IN_MB * 1024**2
            ):
                writer.close()
                writer, data_at, data_bytes = None, F.next_file(*data_at), 0
            if writer is None:
                path = tmp / F.DATA_PATH.format(chunk_index=data_at[0], file_index=data_at[1])
                path.parent.mkdir(parents=True, exist_ok=True)
                writer = pq.ParquetWriter(path, schema, compression="snappy", use_dictionary=True)
            writer.write_table(table)
            data_bytes += table.nbytes
            row: dict[str, Any] = {
                "episode_index": i,
                "tasks": [ep.task],
                "length": ep.length,
                "data/chunk_index": data_at[0],
                "data/file_index": data_at[1],
                "dataset_from_index": frames,
                "dataset_to_index": frames + ep.length,
            }
            if video:
                vid, vid_at = _video_append(tmp, vid, vid_at, vkey, ep, fps)
                start = (vid.frames - ep.length) / fps
                row |= {
                    f"videos/{vkey}/chunk_index": vid_at[0],
                    f"videos/{vkey}/file_index": vid_at[1],
                    f"videos/{vkey}/from_timestamp": start,
                    f"videos/{vkey}/to_timestamp": vid.frames / fps,
                }
            stats = S.episode_stats(_stats_columns(ep, table, feats), feats)
            ep_stats.append(stats)
            rows.append(
                row
                | S.flat(stats)
                | {"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0}
            )
            frames += ep.length
    finally:
        if writer is not None:
            writer.close()
        if vid is not None:
            vid.close()
    if feats is None:
        raise UserError("nothing to write: no episodes")
    if video:
        first = tmp / F.VIDEO_PATH.format(video_key=vkey, chunk_index=0, file_index=0)
        from sim.lerobot.video import video_info

        feats[vkey]["info"] = video_info(first)
    episodes_path = tmp / F.EPISODES_PATH.format(chunk_index=0, file_index=0)
    episodes_path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pylist(rows), episodes_path, compression="snappy")
    pq.write_table(F.tasks_table(list(tasks)), tmp / F.TASKS_PATH)
    info = F.info_json(
        fps=fps,
        features=feats,
        robot_type=robot_type,
        total_episodes=len(rows),
        total_frames=frames,
        total_tasks=len(tasks),
        videos=video,
    )
    (tmp / F.INFO_PATH).write_text(json.dumps(info, indent=4, ensure_ascii=False))
    stats_json = S.to_json(S.aggregate(ep_stats))
    (tmp / F.STATS_PATH).write_text(json.dumps(stats_json, indent=4, ensure_ascii=False))
    size = sum(p.stat().st_size for p in tmp.rglob("*") if p.is_file())
    return len(rows), frames, size


def _video_append(tmp: Path, vid, at: tuple[int, int], key: str, ep: Episode, fps: int):
    """The episode's frames after the current video file's, or in a new file when the current
    one has reached the size limit (LeRobot starts a new file rather than pass it)."""
    from sim.lerobot.video import VideoWriter

    if vid is not None and vid.size_in_mb >= F.VIDEO_FILES_SIZE_IN_MB:
        vid.close()
        vid, at = None, F.next_file(*at)
    if vid is None:
        h, w = ep.frames.shape[1:3]
        path = tmp / F.VIDEO_PATH.format(video_key=key, chunk_index=at[0], file_index=at[1])
        try:
            vid = VideoWriter(path, fps=fps, height=h, width=w)
        except Exception as e:  # the codec refused these frames
            raise UserError(
                f"cannot encode {w}x{h} frames as AV1 video ({e}); use images"
            ) from None
    vid.append(ep.frames)
    return vid, at
