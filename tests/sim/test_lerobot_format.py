"""LeRobotDataset v3.0 written and read without LeRobot (sim.lerobot): the folder's layout,
meta/info.json, the tables' columns and types, meta/stats.json recomputed here from LeRobot's
definitions, frames read back bit-exact from images and within the codec's error from AV1
video, and bad folders refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from sim import get_world
from sim.core import UserError
from sim.lerobot import Dataset, Episode, write_dataset
from sim.lerobot.video import encoder_available

KEY = "observation.images.main"
DEFAULTS = {
    "timestamp": "float32",
    "frame_index": "int64",
    "episode_index": "int64",
    "index": "int64",
    "task_index": "int64",
}
STATS = {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}


def _episode(world, traj, task, role: str) -> Episode:
    t = traj.horizon
    return Episode(
        task.reward.instruction,
        traj.observations[:t],
        traj.actions,
        bool(traj.success),
        {
            "dfa.role": np.array([role] * t, dtype=object),
            "dfa.action_distance": np.linspace(0, 1, t, dtype=np.float32),
        },
    )


@pytest.fixture(scope="module")
def nav_episodes(nav, nav_trajectories):
    return [_episode(nav, traj, task, role) for traj, task, role in nav_trajectories]


@pytest.fixture(scope="module")
def nav_trajectories(nav):
    """Real nav2d trajectories: two tasks' expert demonstrations (two instructions) and a
    rollout that does nothing (it fails)."""
    out = []
    for shift, seed in (("object_ti", 0), ("distractor_ti", 1)):
        task = nav.test_task(shift, seed)
        out.append((nav.demonstrate(task), task, "demonstration"))
    idle = nav.replay(task, np.zeros_like(out[-1][0].actions))
    out.append((idle, task, "failed"))
    return out


@pytest.fixture(scope="module")
def images(tmp_path_factory, nav, nav_episodes):
    root = tmp_path_factory.mktemp("images") / "ds"
    written = write_dataset(
        root, nav_episodes, fps=10, robot_type="nav2d", video=False, action_names=("dx", "dy")
    )
    return root, written


def test_the_folder_holds_what_v3_0_puts_where(images, nav_episodes):
    root, written = images
    files = sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())
    assert files == [
        "data/chunk-000/file-000.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "meta/info.json",
        "meta/stats.json",
        "meta/tasks.parquet",
    ]
    assert not [p for p in root.parent.iterdir() if p.name != "ds"]  # no temporary folder left
    n = sum(e.length for e in nav_episodes)
    assert (written.episodes, written.frames, written.video) == (3, n, False)
    info = json.loads((root / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0"
    assert info["robot_type"] == "nav2d" and info["fps"] == 10
    assert (info["total_episodes"], info["total_frames"], info["total_tasks"]) == (3, n, 2)
    assert info["chunks_size"] == 1000
    assert (info["data_files_size_in_mb"], info["video_files_size_in_mb"]) == (100, 200)
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] is None
    assert info["splits"] == {"train": "0:3"}
    feats = info["features"]
    assert feats[KEY] == {
        "dtype": "image",
        "shape": [36, 36, 3],
        "names": ["height", "width", "channels"],
    }
    assert feats["action"] == {"dtype": "float32", "shape": [2], "names": ["dx", "dy"]}
    assert feats["next.success"]["dtype"] == "bool"
    assert feats["dfa.role"]["dtype"] == "string"
    assert feats["dfa.action_distance"]["dtype"] == "float32"
    for name, dtype in DEFAULTS.items():
        assert feats[name] == {"dtype": dtype, "shape": [1], "names": None}


def test_the_frame_table_has_lerobots_columns_and_types(images, nav_episodes):
    root, _ = images
    table = pq.read_table(root / "data/chunk-000/file-000.parquet")
    types = {f.name: str(f.type) for f in table.schema}
    assert types[KEY] == "struct<bytes: binary, path: string>"
    assert types["action"] == "fixed_size_list<element: float>[2]"
    assert types["next.success"] == "bool" and types["dfa.role"] == "string"
    assert types["timestamp"] == "float"
    for name in ("frame_index", "episode_index", "index", "task_index"):
        assert types[name] == "int64"
    n = table.num_rows
    cols = table.to_pydict()
    assert cols["index"] == list(range(n))
    lengths = [e.length for e in nav_episodes]
    assert cols["episode_index"] == [i for i, t in enumerate(lengths) for _ in range(t)]
    assert cols["frame_index"] == [k for t in lengths for k in range(t)]
    assert np.allclose(cols["timestamp"], np.array(cols["frame_index"]) / 10)
    assert cols["task_index"] == [[0, 1, 1][i] for i in cols["episode_index"]]
    # next.success: on the last frame of an episode that succeeded, nowhere else
    ends = np.cumsum(lengths) - 1
    want = [i in ends and nav_episodes[cols["episode_index"][i]].success for i in range(n)]
    assert cols["next.success"] == want and sum(want) == 2
    assert json.loads(table.schema.metadata[b"huggingface"])["info"]["features"][KEY] == {
        "_type": "Image"
    }


def test_episodes_and_tasks_tables(images, nav_episodes):
    root, _ = images
    rows = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    start = 0
    for i, (row, ep) in enumerate(zip(rows, nav_episodes, strict=True)):
        assert row["episode_index"] == i and row["length"] == ep.length
        assert row["tasks"] == [ep.task]
        assert (row["data/chunk_index"], row["data/file_index"]) == (0, 0)
        assert (row["dataset_from_index"], row["dataset_to_index"]) == (start, start + ep.length)
        assert (row["meta/episodes/chunk_index"], row["meta/episodes/file_index"]) == (0, 0)
        for feature in (KEY, "action", "timestamp", "index", "dfa.action_distance"):
            assert {k.split("/")[-1] for k in row if k.startswith(f"stats/{feature}/")} == STATS
        assert not any(k.startswith("stats/dfa.role/") for k in row)  # strings have none
        start += ep.length
    tasks = pq.read_table(root / "meta/tasks.parquet")
    assert tasks.column_names == ["task_index", "task"]
    assert tasks.to_pydict() == {
        "task_index": [0, 1],
        "task": [nav_episodes[0].task, nav_episodes[1].task],
    }
    pandas = json.loads(tasks.schema.metadata[b"pandas"])
    assert pandas["index_columns"] == ["task"]  # pandas reads the text back as the index


def _histogram_quantile(values: np.ndarray, q: float) -> float:
    """LeRobot's quantile estimate (RunningQuantileStats): 5,000 bins over [min, max] widened
    by 1e-10, interpolated within the bin where the cumulative count reaches q * n."""
    lo, hi = values.min(), values.max()
    edges = np.linspace(lo - 1e-10, hi + 1e-10, 5001)
    hist = np.histogram(values, bins=edges)[0]
    cum = np.cumsum(hist)
    i = int(np.searchsorted(cum, q * len(values)))
    if i == 0:
        return edges[0]
    before = cum[i - 1]
    return edges[i] + (q * len(values) - before) / hist[i] * (edges[i + 1] - edges[i])


def test_stats_are_lerobots(images, nav_episodes):
    root, _ = images
    stats = json.loads((root / "meta/stats.json").read_text())
    assert set(stats) == {
        KEY,
        "action",
        "next.success",
        "next.done",
        "dfa.action_distance",
        *DEFAULTS,
    }
    actions = np.concatenate([e.actions for e in nav_episodes]).astype(np.float64)
    a = stats["action"]
    assert set(a) == STATS and a["count"] == [len(actions)]
    assert np.allclose(a["min"], actions.min(0)) and np.allclose(a["max"], actions.max(0))
    assert np.allclose(a["mean"], actions.mean(0), atol=1e-6)
    assert np.allclose(a["std"], actions.std(0), atol=1e-5)  # pooled over episodes: exact
    # quantiles: each episode's from its histogram, then weighted by the episodes' counts
    rows = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    for key, q in (("q01", 0.01), ("q50", 0.5), ("q99", 0.99)):
        per_episode = []
        for row, ep in zip(rows, nav_episodes, strict=True):
            x = ep.actions.astype(np.float32)
            want = [_histogram_quantile(x[:, d], q) for d in range(2)]
            assert np.allclose(row[f"stats/action/{key}"], want, atol=1e-6)
            per_episode.append((np.array(want), ep.length))
        pooled = sum(v * n for v, n in per_episode) / sum(n for _, n in per_episode)
        assert np.allclose(a[key], pooled, atol=1e-6)
    # images: per channel, in [0, 1], shape (3, 1, 1); every frame sampled in short episodes
    img = stats[KEY]
    frames = np.concatenate([e.frames for e in nav_episodes]).reshape(-1, 3) / 255.0
    assert np.array(img["mean"]).shape == (3, 1, 1)
    assert np.allclose(np.array(img["mean"]).ravel(), frames.mean(0), atol=1e-6)
    assert np.allclose(np.array(img["std"]).ravel(), frames.std(0), atol=1e-5)
    assert np.allclose(np.array(img["max"]).ravel(), frames.max(0))
    assert img["count"] == [sum(e.length for e in nav_episodes)]  # frames, not pixels
    assert stats["index"]["max"] == [sum(e.length for e in nav_episodes) - 1]
    assert stats["next.success"]["mean"] == pytest.approx([2 / len(actions)])


def test_episodes_read_back_bit_exact(images, nav_episodes):
    root, _ = images
    ds = Dataset(root)
    assert len(ds) == 3 and ds.robot_type == "nav2d" and ds.cameras == (KEY,)
    for i, want in enumerate(nav_episodes):
        got = ds.episode(i)
        assert got.task == want.task and got.success == want.success
        assert got.frames.dtype == np.uint8 and np.array_equal(got.frames, want.frames)
        assert got.actions.dtype == np.float32 and np.array_equal(got.actions, want.actions)
        assert list(got.columns["dfa.role"]) == list(want.columns["dfa.role"])
        assert np.array_equal(
            got.columns["dfa.action_distance"], want.columns["dfa.action_distance"]
        )


def test_discrete_actions_are_one_integer_column(tmp_path):
    world = get_world("doorkey")
    task = world.test_task("object_ti", 0)
    demo = world.demonstrate(task)
    ep = Episode(task.reward.instruction, demo.observations[:-1], demo.actions, demo.success)
    root = tmp_path / "ds"
    write_dataset(root, [ep], fps=5, robot_type="doorkey", video=False)
    info = json.loads((root / "meta/info.json").read_text())
    assert info["features"]["action"] == {"dtype": "int64", "shape": [1], "names": None}
    table = pq.read_table(root / "data/chunk-000/file-000.parquet")
    assert str(table.schema.field("action").type) == "int64"
    back = Dataset(root).episode(0)
    assert back.actions.dtype == np.int64 and np.array_equal(back.actions, demo.actions)
    assert np.array_equal(back.frames, demo.observations[:-1])
    stats = json.loads((root / "meta/stats.json").read_text())
    assert np.array(stats["action"]["mean"]).shape == (1,)


def test_video_frames_are_av1_as_lerobot_encodes_them(tmp_path, nav_episodes):
    assert encoder_available()  # PyAV's wheels carry SVT-AV1 and an AV1 decoder
    root = tmp_path / "ds"
    written = write_dataset(root, nav_episodes, fps=10, robot_type="nav2d", video=True)
    assert written.video
    mp4 = root / "videos" / KEY / "chunk-000" / "file-000.mp4"
    assert mp4.is_file()
    info = json.loads((root / "meta/info.json").read_text())
    assert (
        info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    )
    feat = info["features"][KEY]
    assert feat["dtype"] == "video"
    v = feat["info"]
    assert (v["video.codec"], v["video.pix_fmt"]) == ("av1", "yuv420p")
    assert (v["video.height"], v["video.width"], v["video.fps"]) == (36, 36, 10)
    assert (v["video.g"], v["video.crf"], v["video.preset"]) == (2, 30, 12)
    assert v["has_audio"] is False and v["is_depth_map"] is False
    table = pq.read_table(root / "data/chunk-000/file-000.parquet")
    assert KEY not in table.column_names  # the frames are in the video only
    import av

    with av.open(str(mp4)) as c:
        s = c.streams.video[0]
        assert s.codec_context.name in ("libdav1d", "libaom-av1", "av1")
        decoded = sum(1 for _ in c.decode(s))
    assert decoded == sum(e.length for e in nav_episodes)
    rows = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    t = 0.0
    for row, ep in zip(rows, nav_episodes, strict=True):
        assert row[f"videos/{KEY}/from_timestamp"] == pytest.approx(t)
        t += ep.length / 10
        assert row[f"videos/{KEY}/to_timestamp"] == pytest.approx(t)
    ds = Dataset(root)
    for i, want in enumerate(nav_episodes):
        got = ds.episode(i)
        diff = np.abs(got.frames.astype(int) - want.frames.astype(int))
        assert got.frames.shape == want.frames.shape
        assert diff.mean() < 6  # the codec's error, frame by frame in place
        assert np.array_equal(got.actions, want.actions)


def test_a_dataset_is_replaced_only_whole_and_nothing_else_is(tmp_path, nav_episodes):
    root = tmp_path / "ds"
    write_dataset(root, nav_episodes, fps=10, robot_type="nav2d", video=False)
    write_dataset(root, nav_episodes[:1], fps=10, robot_type="nav2d", video=False)
    assert len(Dataset(root)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("keep")
    with pytest.raises(UserError, match="is not a LeRobot dataset"):
        write_dataset(other, nav_episodes, fps=10, robot_type="nav2d", video=False)
    assert [p.name for p in other.iterdir()] == ["mine.txt"]
    a_file = tmp_path / "file"
    a_file.write_text("x")
    with pytest.raises(UserError, match="is a file"):
        write_dataset(a_file, nav_episodes, fps=10, robot_type="nav2d", video=False)


def test_bad_folders_are_one_line(images, tmp_path):
    root, _ = images
    cases = [
        (tmp_path / "missing", "not a LeRobot dataset \\(no such folder\\)"),
        (tmp_path, "not a LeRobot dataset \\(no meta/info.json\\)"),
    ]
    for folder, message in cases:
        with pytest.raises(UserError, match=message) as e:
            Dataset(folder)
        assert "\n" not in str(e.value)
    old = tmp_path / "old"
    (old / "meta").mkdir(parents=True)
    info = json.loads((root / "meta/info.json").read_text()) | {"codebase_version": "v2.1"}
    (old / "meta/info.json").write_text(json.dumps(info))
    with pytest.raises(UserError, match=r"a LeRobotDataset v2\.1; this reads v3\.0"):
        Dataset(old)
    (old / "meta/info.json").write_text("{not json")
    with pytest.raises(UserError, match=r"not a LeRobot info\.json"):
        Dataset(old)
    with pytest.raises(UserError, match="no episode 3; it has episodes 0 to 2"):
        Dataset(root).episode(3)
    with pytest.raises(UserError, match="no camera 'wrist'"):
        Dataset(root).camera("wrist")
