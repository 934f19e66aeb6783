"""LeRobotDataset v3.0 as files: where each part lives, the features, and the tables' schemas.

These are LeRobot's own rules as of its release 0.6.1 (huggingface/lerobot `datasets/utils.py`,
`dataset_metadata.py`, `dataset_writer.py`, `io_utils.py`, `compute_stats.py`,
`video_utils.py`, `configs/video.py`), written down so that a folder written here opens in
LeRobot and a folder LeRobot wrote opens here:

    meta/info.json                                  codebase_version "v3.0", fps, features, totals,
                                                    chunks_size, *_files_size_in_mb, data_path,
                                                    video_path (null without videos), robot_type,
                                                    splits
    meta/stats.json                                 per feature: min, max, mean, std, count,
                                                    q01, q10, q50, q90, q99 (stats.py)
    meta/tasks.parquet                              task_index, indexed by the task's text (pandas)
    meta/episodes/chunk-000/file-000.parquet        a row per episode: where its frames and video
                                                    lie, its tasks, length and stats/<key>/<stat>
    data/chunk-000/file-000.parquet                 a row per frame, episode after episode
    videos/<key>/chunk-000/file-000.mp4             a video feature's frames, episode after episode

A frame's columns are its features: `observation.images.<camera>` (an "image" is a PNG held in
the table, a "video" a frame of the mp4), `action`, `next.success`, ..., and LeRobot's own
`timestamp` (float32, seconds), `frame_index`, `episode_index`, `index`, `task_index` (int64).
A feature of shape (1,) is a plain column; (n,) a fixed-size list of n values.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import pyarrow as pa

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000  # files per chunk folder
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200

INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
TASKS_PATH = "meta/tasks.parquet"
EPISODES_DIR = "meta/episodes"
CHUNK_FILE = "chunk-{chunk_index:03d}/file-{file_index:03d}"
EPISODES_PATH = EPISODES_DIR + "/" + CHUNK_FILE + ".parquet"
DATA_PATH = "data/" + CHUNK_FILE + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE + ".mp4"

DEFAULT_FEATURES: dict[str, dict[str, Any]] = {
    "timestamp": {"dtype": "float32", "shape": (1,), "names": None},
    "frame_index": {"dtype": "int64", "shape": (1,), "names": None},
    "episode_index": {"dtype": "int64", "shape": (1,), "names": None},
    "index": {"dtype": "int64", "shape": (1,), "names": None},
    "task_index": {"dtype": "int64", "shape": (1,), "names": None},
}
IMAGE_NAMES = ["height", "width", "channels"]
IMAGES_PREFIX = "observation.images."
ACTION = "action"
SUCCESS = "next.success"
DONE = "next.done"

# LeRobot's default video encoding (configs/video.py, VideoEncoderConfig): AV1 by SVT-AV1, 4:2:0,
# a key frame every second frame, constant quality 30, SVT's fastest preset, no fast-decode
# tuning, encoded through PyAV. ENCODER is what meta/info.json records of it (video.<field>).
VIDEO_CODEC = "libsvtav1"
PIX_FMT = "yuv420p"
ENCODER = {
    "pix_fmt": PIX_FMT,
    "g": 2,
    "crf": 30,
    "preset": 12,
    "fast_decode": 0,
    "video_backend": "pyav",
    "extra_options": {},
}
VIDEO_OPTIONS = {"g": "2", "crf": "30", "preset": "12", "svtav1-params": "fast-decode=0"}

NUMERIC = ("float32", "float64", "int64", "int32", "bool")


def arrow_type(feature: Mapping[str, Any]) -> pa.DataType:
    """The column type `datasets` gives a feature (LeRobot's get_hf_features_from_features):
    an image is a struct of PNG bytes and a file name; shape (1,) a plain value; (n,) a
    fixed-size list of n values."""
    dtype, shape = feature["dtype"], tuple(feature["shape"])
    if dtype == "image":
        return pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    value = pa.string() if dtype == "string" else pa.from_numpy_dtype(dtype)
    if shape == (1,):
        return value
    if len(shape) == 1:
        return pa.list_(value, shape[0])
    raise ValueError(f"a feature of shape {shape} is not written here (1-D features only)")


def hf_feature(feature: Mapping[str, Any]) -> dict[str, Any]:
    """The feature as `datasets` describes it in a table's "huggingface" schema metadata."""
    dtype, shape = feature["dtype"], tuple(feature["shape"])
    if dtype == "image":
        return {"_type": "Image"}
    value = {"dtype": dtype, "_type": "Value"}
    if shape == (1,):
        return value
    return {"feature": value, "length": shape[0], "_type": "List"}


def frame_schema(features: Mapping[str, Mapping[str, Any]]) -> pa.Schema:
    """The data files' schema: a column per feature but videos, with the metadata `datasets`
    writes, so that `datasets.Dataset.from_parquet` reads images back as images."""
    stored = {k: f for k, f in features.items() if f["dtype"] != "video"}
    meta = {"info": {"features": {k: hf_feature(f) for k, f in stored.items()}}}
    return pa.schema(
        [pa.field(k, arrow_type(f)) for k, f in stored.items()],
        metadata={"huggingface": json.dumps(meta)},
    )


def tasks_table(tasks: list[str]) -> pa.Table:
    """meta/tasks.parquet as pandas writes LeRobot's frame of task_index indexed by the task's
    text (an index named "task"; LeRobot reads it with pandas.read_parquet and looks tasks up
    by the index)."""
    columns = [("task_index", "int64", "int64"), ("task", "unicode", "object")]
    pandas_meta = {
        "index_columns": ["task"],
        "column_indexes": [
            {
                "name": None,
                "field_name": None,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": {"encoding": "UTF-8"},
            }
        ],
        "columns": [
            {"name": n, "field_name": n, "pandas_type": p, "numpy_type": t, "metadata": None}
            for n, p, t in columns
        ],
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.3",
    }
    schema = pa.schema(
        [("task_index", pa.int64()), ("task", pa.string())],
        metadata={"pandas": json.dumps(pandas_meta)},
    )
    return pa.table(
        {"task_index": pa.array(range(len(tasks)), pa.int64()), "task": tasks}, schema=schema
    )


def task_texts(table: pa.Table) -> list[str]:
    """The tasks in task_index order, from meta/tasks.parquet as LeRobot writes it (the text in
    the pandas index, named "task" in newer files, or in a column "task")."""
    names = table.column_names
    text = next((n for n in ("task", "__index_level_0__") if n in names), None)
    if text is None or "task_index" not in names:
        raise ValueError(f"columns {names}; expected task_index and the task's text")
    pairs = sorted(zip(table["task_index"].to_pylist(), table[text].to_pylist(), strict=True))
    if [i for i, _ in pairs] != list(range(len(pairs))):
        raise ValueError("task_index is not 0, 1, 2, ...")
    return [t for _, t in pairs]


def info_json(
    *,
    fps: int,
    features: Mapping[str, Mapping[str, Any]],
    robot_type: str | None,
    total_episodes: int,
    total_frames: int,
    total_tasks: int,
    videos: bool,
) -> dict[str, Any]:
    """meta/info.json in LeRobot's key order (create_empty_dataset_info, then save_episode)."""
    return {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": robot_type,
        "total_episodes": total_episodes,
        "total_frames": total_frames,
        "total_tasks": total_tasks,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
        "fps": fps,
        "splits": {"train": f"0:{total_episodes}"},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if videos else None,
        "features": {k: {**f, "shape": list(f["shape"])} for k, f in features.items()},
    }


def next_file(chunk: int, file: int) -> tuple[int, int]:
    """The file after (chunk, file): chunks hold CHUNKS_SIZE files (update_chunk_file_indices)."""
    return (chunk + 1, 0) if file == CHUNKS_SIZE - 1 else (chunk, file + 1)
