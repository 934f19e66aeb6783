import csv
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from PIL import Image

from dfa_viz.cli import main
from dfa_viz.configs import Finetuning
from dfa_viz.experiment.conditions import ACCURACY, PAPER, PAPER_BUDGETS, choose
from dfa_viz.experiment.experiment import Plan, run_experiment
from dfa_viz.experiment.results import cf_beats_baseline, results_folder, summarise
from dfa_viz.experiment.runner import COLUMNS, Settings, nh_random_variants, prepare
from sim import PAPER_WORLDS, get_world
from sim.core import UserError

# a tiny experiment: one world, one shift, every condition, two budgets, one seed
PLAN = Plan(worlds=("nav2d",), shifts=("object",), budgets=(2, 5), seeds=(0,))
SETTINGS = Settings(finetuning=Finetuning(steps=40, steps_per_trajectory=1))
N_RUNS = 4 * 2


def _run(out: Path, backend: str):
    return run_experiment(
        PLAN, out=out, settings=SETTINGS, backend=backend, workers=2, progress=False
    )


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("q2-local")
    return _run(out, "local")


# -- the experiment end to end ---------------------------------------------------------------------
@pytest.mark.slow
def test_tiny_experiment_runs_every_run(local_run):
    assert (local_run.planned, local_run.skipped, local_run.executed) == (N_RUNS, 0, N_RUNS)
    with (local_run.out / "runs.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == N_RUNS and tuple(rows[0]) == COLUMNS
    assert {r["condition"] for r in rows} == {"nh_random", "baseline_h", "cf_h", "oracle"}
    for r in rows:
        assert 0.0 <= float(r["success"]) <= 1.0
        assert int(r["n_distinct"]) <= int(r["budget"])
    oracle = [r for r in rows if r["condition"] == "oracle"]
    assert all(r["chosen_concept"] == r["right_concept"] and r["correct"] == "1" for r in oracle)
    cf = [r for r in rows if r["condition"] == "cf_h"]
    assert all(r["cf_edit"] for r in cf), "CF H records the search's answer"


@pytest.mark.slow
def test_ray_backend_gives_an_identical_csv(local_run, tmp_path):
    summary = _run(tmp_path / "q2-ray", "ray")
    assert summary.executed == N_RUNS
    ours = (tmp_path / "q2-ray" / "runs.csv").read_bytes()
    assert ours == (local_run.out / "runs.csv").read_bytes()


@pytest.mark.slow
def test_resume_skips_finished_runs(local_run, tmp_path):
    out = tmp_path / "resumed"
    shutil.copytree(local_run.out, out)
    full = (out / "runs.csv").read_text()
    lines = full.splitlines(keepends=True)
    # an interrupted experiment: three runs finished, a fourth cut off in mid-line
    (out / "runs.csv").write_text("".join(lines[:4]) + lines[4][:15])
    summary = _run(out, "local")
    assert (summary.skipped, summary.executed) == (3, N_RUNS - 3)
    assert (out / "runs.csv").read_text() == full
    again = _run(out, "local")
    assert (again.skipped, again.executed) == (N_RUNS, 0)


@pytest.mark.slow
def test_table_plot_and_recording(local_run):
    table = (local_run.out / "table.md").read_text()
    assert "## nav2d, object shift" in table
    assert "| Oracle | " in table and "(0.8)" in table, "the paper's number sits beside ours"
    png = local_run.out / "plots" / "nav2d-object.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(png) as im:
        assert im.width > 200 and im.height > 200
        pixels = np.asarray(im.convert("RGB"))
    assert pixels.std() > 10, "the plot is not blank"
    series = {}
    for chunk in rr.chunk.RrdReader(local_run.out / "curves.rrd").store().stream():
        d = chunk.to_record_batch().to_pydict()
        if "budget" in d:
            series[str(chunk.entity_path)] = d["budget"]
    for c in ("nh_random", "baseline_h", "cf_h", "oracle"):
        assert series[f"/nav2d/object/{c}/mean"] == [2, 5]
        assert series[f"/nav2d/object/{c}/paper"] == list(PAPER_BUDGETS)


@pytest.mark.slow
def test_other_settings_do_not_mix_into_a_folder(local_run):
    with pytest.raises(UserError, match="another --out"):
        results_folder(local_run.out, Settings(finetuning=Finetuning(steps=41)))


@pytest.mark.slow
def test_cli_resumes_a_finished_folder_and_rewrites_its_reports(local_run, tmp_path, capsys):
    out = tmp_path / "again"
    shutil.copytree(local_run.out, out)
    (out / "table.md").unlink()
    args = ["experiment", "q2", "--world", "nav2d", "--shift", "object", "--budgets", "2", "5"]
    args += ["--seeds", "1", "--steps", "40", "--steps-per-trajectory", "1"]
    assert main([*args, "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert f"{N_RUNS} runs planned: {N_RUNS} already in {out}, 0 run now" in printed
    assert (out / "table.md").is_file()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--budgets", "0"], "budgets"),
        (["--seeds", "0"], "--seeds"),
        (["--replay-share", "1"], "--replay-share"),
        (["--steps", "0"], "--steps must be at least 1"),
    ],
)
def test_cli_rejects_bad_numbers(tmp_path, capsys, args, message):
    assert main(["experiment", "q2", *args, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_cli_rejects_unknown_worlds_and_experiments(tmp_path):
    with pytest.raises(SystemExit):
        main(["experiment", "q2", "--world", "atlantis", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        main(["experiment", "q9", "--out", str(tmp_path)])


# -- the parts ------------------------------------------------------------------------------------
def test_the_paper_numbers_are_all_there():
    for world in PAPER_WORLDS:
        for shift in ("object", "distractor"):
            assert 0 < ACCURACY[(world, shift)][0] < ACCURACY[(world, shift)][1] < 1
            for c in ("nh_random", "baseline_h", "cf_h", "oracle"):
                assert len(PAPER[(world, shift, c)]) == len(PAPER_BUDGETS)


def test_interchangeable_slots_make_one_user_concept():
    names = {uc.name: uc.members for uc in get_world("doorkey").space.user_concepts()}
    assert names["lava.presence"] == (
        ("lava0", "presence"),
        ("lava1", "presence"),
        ("lava2", "presence"),
    )
    assert set(names) == {
        "key.colour",
        "door.colour",
        "goal.colour",
        "lava.presence",
        "lava.colour",
    }


def test_simulated_users_are_right_at_the_paper_rate():
    visible = ("goal.colour", "goal.shape", "distractor.presence")
    kw = dict(world="nav2d", shift="object", right="goal.colour", visible=visible)
    n = 2000
    base = [choose("baseline_h", seed=s, **kw) for s in range(n)]
    cf = [choose("cf_h", seed=s, offered=("goal.colour",), **kw) for s in range(n)]
    blind = [choose("cf_h", seed=s, offered=(), **kw) for s in range(n)]
    assert abs(np.mean([c.correct for c in base]) - 0.28) < 0.04
    assert abs(np.mean([c.correct for c in cf]) - 0.97) < 0.02
    assert not any(c.correct for c in blind), "no counterfactual, no right answer"
    # common random numbers: CF H is right whenever Baseline H is (and its search was right)
    assert all(c.correct for b, c in zip(base, cf, strict=True) if b.correct)
    wrong = Counter(c.concept for c in base if not c.correct)
    assert set(wrong) == {"goal.shape", "distractor.presence"}
    assert choose("oracle", seed=0, **kw).concept == "goal.colour"
    assert choose("nh_random", seed=0, **kw).concept is None


def test_random_concepts_cover_the_visible_ones(nav, nav_policy):
    from dfa_viz.configs import AdaptConfig

    prep = prepare("nav2d", "distractor", 1, 10)
    many = nh_random_variants(nav, prep, AdaptConfig(budget=61), seed=1)
    few = nh_random_variants(nav, prep, AdaptConfig(budget=21), seed=1)
    assert len(many) == 60
    assert [t.scenes for t in many[:20]] == [t.scenes for t in few]
    other = nh_random_variants(nav, prep, AdaptConfig(budget=61), seed=2)
    assert [t.scenes for t in many] != [t.scenes for t in other]


def test_cf_h_against_baseline_h_is_paired_over_budget_and_seed():
    rows = [
        {
            "world": "nav2d",
            "shift": "object",
            "condition": c,
            "budget": str(b),
            "seed": str(s),
            "success": str(v),
        }
        for c, v in (("cf_h", 0.9), ("baseline_h", 0.4))
        for b in (5, 10)
        for s in range(4)
    ]
    text = cf_beats_baseline(rows, "nav2d", "object")
    assert "over 8 runs paired by budget and seed: +0.50" in text and "(significant" in text
    same = [dict(r, success="0.5") for r in rows]
    assert "identical; not significant" in cf_beats_baseline(same, "nav2d", "object")


def test_confidence_interval():
    one = summarise([0.5])
    assert one.n == 1 and np.isnan(one.half_width) and one.low == one.high == 0.5
    cell = summarise([0.2, 0.4, 0.6, 0.8, 1.0])
    assert cell.mean == pytest.approx(0.6)
    assert cell.half_width == pytest.approx(
        2.776 * np.std([0.2, 0.4, 0.6, 0.8, 1.0], ddof=1) / 5**0.5
    )
    assert summarise([1.0, 1.0]).high == 1.0
