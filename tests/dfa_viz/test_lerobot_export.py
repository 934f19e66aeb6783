"""`dfa export lerobot --from FOLDER`: a `dfa sweep` folder's example failures and a page
session's runs written as LeRobotDatasets and read back as the trajectories they came from;
frames as AV1 video for camera worlds and PNG images for the worlds drawn to the pixel."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from dfa_viz.cli import main
from dfa_viz.lerobot.export import video_for
from dfa_viz.lerobot.sources import parse_edit
from policy import base_policy, failing_test_task
from search.sweep import Example, failure_task
from sim import get_world
from sim.core import Scene
from sim.lerobot import Dataset

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "nav2d"
    args = ["--world", "nav2d", "--tasks", "4", "--sizes", "1", "--worst", "1", "--no-progress"]
    proc = subprocess.run(
        [sys.executable, "-m", "dfa_viz.cli", "sweep", *args, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr
    return out


def _examples(folder):
    with (folder / "sweep.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if r["kind"] in ("single", "pair")]
    seen = []
    for r in rows:
        if r["example_seed"]:
            key = (int(r["example_seed"]), r["example_edit"], r["example_pos"])
            if key not in seen:
                seen.append(key)
    return seen


def test_a_sweeps_failures_are_exported_with_the_experts_demonstrations(sweep, tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(["export", "lerobot", "--from", str(sweep), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "a LeRobotDataset v3.0" in printed and "PNG images" in printed
    nav = get_world("nav2d")
    policy = base_policy(nav)
    ds = Dataset(out)
    examples = _examples(sweep)
    assert examples and len(ds) == 2 * len(examples)  # the expert solves every nav2d failure
    for k, (seed, edit, pos) in enumerate(examples):
        place = tuple(float(v) for v in pos.split()) or None
        task = failure_task(nav, Example(seed, parse_edit(edit), False, place))
        demo, failed = ds.episode(2 * k), ds.episode(2 * k + 1)
        for ep, role, traj in (
            (demo, "demonstration", nav.demonstrate(task)),
            (failed, "failed", nav.rollout(task, policy)),
        ):
            assert ep.text("dfa.role") == role and ep.text("dfa.edit") == edit
            assert np.array_equal(ep.frames, traj.observations[: traj.horizon])
            assert np.array_equal(ep.actions, traj.actions)
            assert ep.success == traj.success
            assert Scene.from_dict(json.loads(ep.columns["dfa.scene"][0])) == task.scene
        assert demo.success and not failed.success


def test_video_frames_on_request_and_for_camera_worlds(sweep, tmp_path, capsys):
    assert video_for(get_world("tabletop"), "auto")[0]  # a camera's frames
    assert not video_for(get_world("nav2d"), "auto")[0]  # drawn to the pixel
    assert not video_for(get_world("doorkey"), "auto")[0]
    out = tmp_path / "ds"
    argv = ["export", "lerobot", "--from", str(sweep), "--out", str(out), "--frames", "video"]
    assert main(argv) == 0
    assert "AV1 video" in capsys.readouterr().out
    info = json.loads((out / "meta/info.json").read_text())
    assert info["features"]["observation.images.main"]["dtype"] == "video"
    assert (out / "videos/observation.images.main/chunk-000/file-000.mp4").is_file()
    images = tmp_path / "images"
    assert main(["export", "lerobot", "--from", str(sweep), "--out", str(images)]) == 0
    a, b = Dataset(out), Dataset(images)
    for i in range(len(a)):
        va, vb = a.episode(i), b.episode(i)
        assert np.array_equal(va.actions, vb.actions)
        assert np.abs(va.frames.astype(int) - vb.frames.astype(int)).mean() < 4


def test_a_page_sessions_run_is_exported(tmp_path, capsys):
    from dfa_viz.app import events as E
    from dfa_viz.app.sessions import Session
    from dfa_viz.loop import diagnose
    from search import SearchConfig
    from sim.core import Label

    nav = get_world("nav2d")
    policy = base_policy(nav)
    task, _ = failing_test_task(nav, policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    folder = tmp_path / "session"
    session = Session.open(folder, world="nav2d")
    demo.save(folder / "demo-0003.npz")
    diagnosis = diagnose(nav, policy, task, demo, config=SearchConfig.for_world(nav, max_size=1))
    edit = diagnosis.edit
    change = edit.ordered[0]
    label = Label(
        change.slot, change.concept, False, tuple(nav.space.values(change.slot, change.concept))
    )
    for event in (
        E.TaskLoaded("nav2d", "object_ti", 0, task.seed),
        E.Judged(True),
        E.Demonstrated("demo-0003.npz", "keys"),
        E.Searched(diagnosis.result),
        E.Marked(label),
    ):
        session.append(event)
    session.close()
    out = tmp_path / "ds"
    assert main(["export", "lerobot", "--from", str(folder), "--out", str(out)]) == 0, (
        capsys.readouterr().err
    )
    ds = Dataset(out)
    roles = [ds.episode(i).text("dfa.role") for i in range(len(ds))]
    n = len(diagnosis.counterfactuals)
    assert roles == ["demonstration", *["counterfactual"] * n, "failed"]
    first = ds.episode(0)
    assert np.array_equal(first.frames, demo.observations[:-1])
    cf = ds.episode(1)
    shown = diagnosis.counterfactuals[diagnosis.tie]
    assert np.array_equal(cf.frames, shown.observations[:-1])
    assert cf.text("dfa.edit") == str(diagnosis.result.counterfactuals[diagnosis.tie].edit)
    assert cf.text("dfa.label") == "TI"
    failed = ds.episode(len(ds) - 1)
    assert np.array_equal(failed.actions, nav.rollout(task, policy).actions)
    assert set(failed.columns["dfa.run"]) == {"nav2d object_ti seed 0 session session task 0"}


def test_a_q2_experiments_runs_are_exported(tmp_path, capsys):
    from dfa_viz.experiment.runner import prepare

    q2 = tmp_path / "q2"
    argv = ["experiment", "q2", "--world", "nav2d", "--shift", "object", "--budgets", "2"]
    argv += ["--seeds", "1", "--conditions", "oracle", "--steps", "40"]
    argv += ["--steps-per-trajectory", "1", "--workers", "1", "--no-progress", "--out", str(q2)]
    assert main(argv) == 0, capsys.readouterr().err
    out = tmp_path / "ds"
    assert main(["export", "lerobot", "--from", str(q2), "--out", str(out)]) == 0
    capsys.readouterr()
    with (q2 / "runs.csv").open() as f:
        (row,) = list(csv.DictReader(f))
    ds = Dataset(out)
    episodes = [ds.episode(i) for i in range(len(ds))]
    assert [e.text("dfa.role") for e in episodes] == ["demonstration", "variant", "failed"]
    assert {e.text("dfa.run") for e in episodes} == {"nav2d object oracle 2 0"}
    prep = prepare("nav2d", "object", 0, 10)
    assert str(prep.task.seed) == row["task_seed"]
    assert np.array_equal(episodes[0].frames, prep.demo.observations[:-1])
    variant = episodes[1]
    assert variant.text("dfa.concept") == row["right_concept"] == "goal.shape"
    assert variant.text("dfa.label") == "TI" and variant.success
    assert not episodes[2].success
