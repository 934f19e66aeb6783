"""`dfa sweep`: the files it writes and reads back, the backends agreeing, the base policies'
weak spots ranked first, bad input, and a failure it found loaded as a session's task."""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest
import rerun as rr
from PIL import Image

from dfa_viz.app import events as E
from dfa_viz.app import replay as R
from dfa_viz.cli import main
from dfa_viz.sweep.figures import heatmap
from dfa_viz.sweep.run import SweepJob, backend_runner
from policy import base_policy
from search.sweep import failure_task, plan, sweep, sweep_tasks
from sim import get_world
from sim.core import PRESENCE, UserError

pytestmark = pytest.mark.slow


def _ray() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def test_the_command_writes_the_table_the_heatmap_and_the_recording(tmp_path):
    out = tmp_path / "sweep"
    args = ["--world", "nav2d", "--tasks", "9", "--sizes", "1", "2", "--worst", "2"]
    proc = subprocess.run(
        [sys.executable, "-m", "dfa_viz.cli", "sweep", *args, "--out", str(out), "--no-progress"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    assert "goal.colour" in proc.stdout and "most damaging" in proc.stdout
    assert "(by Δ, largest first)" in proc.stdout  # each table says what it is ranked by
    with (out / "sweep.csv").open() as f:
        rows = list(csv.DictReader(f))
    kinds = [r["kind"] for r in rows]
    assert kinds[0] == "concept" and "single" in kinds and "pair" in kinds
    first = rows[0]
    assert (first["slot"], first["concept"]) == ("goal", "colour")
    singles = [r for r in rows if r["kind"] == "single"]
    diffs = [float(r["difference"]) for r in singles if r["difference"]]
    assert diffs == sorted(diffs, reverse=True)  # most damaging first: above the control arm
    counted = [r for r in singles if r["counted"] != "0"]
    assert all(float(r["failure_low"]) <= float(r["failure_rate"]) for r in counted)
    assert all(int(r["counted"]) <= 9 for r in counted)  # 9 distinct layouts, each once
    for r in counted:
        control = float(r["control_rate"])
        assert float(r["success_rate_control"]) == pytest.approx(1 - control)
        assert float(r["difference"]) == pytest.approx(float(r["failure_rate"]) - control)
        assert float(r["difference_low"]) <= float(r["difference"]) <= float(r["difference_high"])
    with Image.open(out / "heatmap.png") as img:
        png = np.asarray(img)
    assert png.ndim == 3 and png.shape[0] > 200
    store = rr.chunk.RrdReader(out / "sweep.rrd").store()
    entities = {str(c.entity_path) for c in store.stream()}
    for entity in (
        "/sweep/heatmap",
        "/sweep/summary",
        "/sweep/concepts/goal.colour",
        "/rollouts/worst0/unedited/frame",
        "/rollouts/worst0/edited/frame",
        "/rollouts/worst1/edited/action/0",
    ):
        assert entity in entities, entity


@pytest.mark.parametrize(
    "args",
    [
        ("sweep", "--tasks", "0"),
        ("sweep", "--sizes", "3"),
        ("sweep", "--world", "nowhere"),
        ("sweep", "--workers", "0"),
        ("sweep", "--policy", "no/such/folder"),
    ],
)
def test_bad_input_is_one_line(args, tmp_path, capsys):
    assert main([*args, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dfa: error:")
    assert not (tmp_path / "o").exists()


def test_the_backends_agree():
    """Units run here, on a pool of two processes and on Ray (where installed) give the same
    sweep: results are put in order by unit, and every unit runs with one torch thread."""
    world = get_world("doorkey")
    tasks = sweep_tasks(world, 10)
    job = SweepJob("doorkey")
    policy = base_policy(world)
    assert len(plan(tasks).units(world)) == 3  # so that they finish in some order
    here = sweep(world, policy, tasks, runner=backend_runner(job, workers=1))
    pool = sweep(world, policy, tasks, runner=backend_runner(job, workers=2))
    assert len(here.seeds) == 10 and here.rollouts > 1000
    assert pool == here
    if _ray():
        on_ray = sweep(world, policy, tasks, runner=backend_runner(job, backend="ray", workers=2))
        assert on_ray == here


@pytest.mark.parametrize(
    ("world", "tasks", "top"),
    [("nav2d", 20, 2), ("doorkey", 10, 3), ("tabletop", 2, 4)],
)
def test_base_policies_break_first_on_the_concepts_their_shifts_plant(world, tasks, top):
    """Each base policy is cloned on one look: the concepts its object_ti shifts change come
    first, and in DoorKey a lava tile on the path ranks beside the key's colour."""
    w = get_world(world)
    result = sweep(w, base_policy(w), sweep_tasks(w, tasks))
    planted = {w.test_task("object_ti", s).cause for s in range(20)}
    first = result.concepts[0]
    assert (first.slot, first.concept) in planted
    looks = [(c.slot, c.concept) for c in result.concepts if c.concept != PRESENCE and c.n]
    assert set(looks[:top]) <= planted
    if world == "doorkey":
        ranks = [result.concept_rank(s, PRESENCE) for s in ("lava0", "lava1", "lava2")]
        assert max(ranks) <= 4 and result.cell("lava0", PRESENCE, "present").failure_rate > 0.6


def test_heatmap_cells_are_where_it_says():
    w = get_world("nav2d")
    result = sweep(w, base_policy(w), sweep_tasks(w, 9))
    picture = heatmap(w.space, result)
    for cell in result.cells:
        assert picture.cell_at(*picture.centre(cell.key)) == cell.key
    assert picture.cell_at(0.0, 0.0) is None
    assert np.array_equal(picture.image, heatmap(w.space, result).image)


def test_a_failure_found_is_a_session_task(tmp_path):
    """The page loads a sweep's failure as a TaskLoaded event with its edit and place; the
    event reads back and rebuilds the same task."""
    w = get_world("doorkey")
    policy = base_policy(w)
    result = sweep(w, policy, sweep_tasks(w, 1))
    ex = result.cell("lava0", PRESENCE, "present").example
    assert ex is not None and ex.pos is not None
    event = E.TaskLoaded("doorkey", E.SWEEP, ex.seed, ex.seed, ex.edit, ex.pos)
    back = E.from_json({"type": "task", **event.to_json()})
    assert back == event
    rebuild = R.Rebuild(policy=lambda _: policy, trajectory=None, checkpoint=None)  # type: ignore[arg-type]
    record = R.apply(None, back, rebuild)
    assert record.task.scene == failure_task(w, ex).scene and not record.rollout.success
    with pytest.raises(UserError):
        E.from_json({"type": "task", **event.to_json(), "shift": "object_ti"})
    old = E.from_json(
        {"type": "task", "world": "nav2d", "shift": "object_ti", "seed": 0, "task_seed": 0}
    )
    assert old.edit is None  # sessions written before keep loading


def test_the_bench_times_the_sweep_against_its_forward_bound():
    from dfa_viz.bench.sweep import bench_sweep

    r = bench_sweep("nav2d", tasks=9)
    assert r["distinct"] == 9 and r["frames"] == r["rollouts"] * 20
    assert r["wall_s"] > 0 and r["to_bound"] >= 1.0  # never faster than its bound (no clock)
