"""`dfa experiment unplanted`: one nav2d compound task measured end to end into a results
folder, bad input as one line with exit 2, and the table in the paper's world order."""

import csv
import json
import re
from pathlib import Path

import pytest

from dfa_viz.cli import main
from dfa_viz.experiment.unplanted import SALIENCY_COLUMNS, TASK_COLUMNS, run_world
from dfa_viz.experiment.unplanted_table import merge, read_csv, table
from dfa_viz.records import world_order
from search.planted import fit_on_planted


def test_one_task_measured_into_a_folder(nav, nav_policy, tmp_path):
    prior, _ = fit_on_planted(nav, nav_policy, n=2)
    rows, sal, drawn = run_world(
        nav, nav_policy, "compound", 1, seed=0, prior=prior, policy_name="base",
        tries=50, methods=("grad_cam",),
    )  # fmt: skip
    (row,) = rows
    assert drawn >= 1 and tuple(row) == TASK_COLUMNS
    assert row["gt_size"] in ("1", "2") and int(row["gt_count"]) >= 1
    assert row["cf_in_gt"] in ("0", "1") and int(row["cf_rollouts"]) >= 1
    rank, n_at = int(row["prior_rank"]), int(row["n_at_size"])
    assert 1 <= rank <= n_at and 1 <= int(row["enum_rank"]) <= n_at
    assert {r["method"] for r in sal} == {"grad_cam", "random"} and len(sal) == 5  # 4 readouts
    assert all(tuple(r) == SALIENCY_COLUMNS and r["hit"] in ("0", "1") for r in sal)
    run = {"world": "nav2d", "policy": "base", "kind": "compound", "command": "dfa ...",
           "tasks": 1, "candidates": drawn, "wall_s": 1.0, "prior": "test"}  # fmt: skip
    merge(tmp_path, rows, sal, run)
    merge(tmp_path, rows, sal, run)  # the same run again replaces its rows
    with (tmp_path / "tasks.csv").open() as f:
        assert list(csv.DictReader(f)) == rows
    assert len(json.loads((tmp_path / "runs.json").read_text())) == 1
    text = (tmp_path / "table.md").read_text()
    assert "| nav2d | base | compound | 1 |" in text and "Grad-CAM" in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tasks", "0"], "--tasks must be at least 1, not 0"),
        (["--kind", "moved", "--world", "nosuch"], "nosuch"),
        (["--tries", "1", "--tasks", "2"], "--tries 1 is fewer than --tasks 2"),
        (["--seed", "-1"], "seed must be an integer"),
        (["--prior-tasks", "-1"], "--prior-tasks must be 0 (no prior) or more, not -1"),
        (["--prior-fit", "others", "--tasks", "1"], "--prior-fit others fits on the run's"),
    ],
)
def test_bad_input_is_one_line_exit_2(args, message, capsys, tmp_path):
    assert main(["experiment", "unplanted", "--out", str(tmp_path / "o"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_cross_fitted_priors_leave_each_task_out(nav, nav_policy):
    from dfa_viz.experiment.unplanted import NONE, cross_fitted, prior_rank_of
    from search.enumerate import singles
    from search.lockstep import rollout_lockstep
    from search.prior import SearchLog, fit, unedited_candidate

    logs, rows = [], []
    for seed in range(3):
        task = nav.train_task(seed)
        demo = nav.demonstrate(task)
        every = singles(nav.space, task.scene)
        tried = rollout_lockstep(nav, nav_policy, task.scene, demo, every, epsilon=nav.epsilon)
        # two colour changes are this task's answers (labels any edit could carry)
        answer = tuple(e for e in every if next(iter(e.changes)).concept == "colour")[:2]
        assert answer
        unedited = unedited_candidate(nav, nav_policy, task.scene, demo)
        logs.append(SearchLog(task.scene, unedited, tuple(tried), answer))
        rows.append({"gt_size": "1", "prior_rank": NONE, "n_at_size": str(len(every))})
    rows.insert(1, {"gt_size": NONE, "prior_rank": NONE, "n_at_size": NONE})  # no ground truth
    scenes = [nav.train_task(s).scene for s in range(5)]
    assert cross_fitted(nav, rows[:1], logs[:1], scenes=scenes)[0]["prior_rank"] == NONE
    ranked = cross_fitted(nav, rows, logs, scenes=scenes)
    assert ranked[1] == rows[1] and rows[0]["prior_rank"] == NONE  # rows left as they were
    for row, j in zip([ranked[0], ranked[2], ranked[3]], range(3), strict=True):
        alone = fit(nav, logs[:j] + logs[j + 1 :], scenes)  # every other task, never this one
        assert row["prior_rank"] == str(prior_rank_of(nav, alone, logs[j], logs[j].singles))
        assert 1 <= int(row["prior_rank"]) <= int(row["n_at_size"])


def test_the_table_lists_worlds_in_the_papers_order_whichever_ran_last():
    out = Path(__file__).parents[2] / "docs" / "results" / "unplanted"
    tasks = read_csv(out / "tasks.csv", TASK_COLUMNS)
    sals = read_csv(out / "saliency.csv", SALIENCY_COLUMNS)
    runs = json.loads((out / "runs.json").read_text())
    text = table(tasks, sals, runs)
    assert table(tasks[::-1], sals, runs[::-1]) == text
    commands = [line for line in text.splitlines() if line.startswith("- `dfa experiment")]
    worlds = [line.split("--world ")[1].split()[0] for line in commands]
    assert worlds == sorted(worlds, key=world_order) and len(set(worlds)) >= 3


def test_a_random_order_that_misses_too_few_tasks_to_test_against_is_said_so():
    out = Path(__file__).parents[2] / "docs" / "results" / "unplanted"
    said = re.findall(
        r"the random order's object top-1 is [^\[]*\[(\d+)/(\d+)\]( \(it misses (\d+):)?",
        (out / "table.md").read_text(),
    )
    misses = [int(n) - int(k) for k, n, _, _ in said]
    assert {m <= 4 for m in misses} == {True, False}  # both kinds are in the table
    for (_, _, caveat, shown), m in zip(said, misses, strict=True):  # 1/2^5 < 0.05
        assert bool(caveat) == (m <= 4) and (not caveat or int(shown) == m)
