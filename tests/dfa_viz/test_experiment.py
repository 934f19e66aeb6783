import csv
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from PIL import Image
from scipy.stats import binomtest, wilcoxon

from dfa_viz.cli import main
from dfa_viz.configs import Finetuning
from dfa_viz.experiment import seed_test
from dfa_viz.experiment.conditions import ACCURACY, PAPER, PAPER_BUDGETS, choose, condition_label
from dfa_viz.experiment.experiment import Plan, run_experiment
from dfa_viz.experiment.results import results_folder, same_as_oracle, summarise
from dfa_viz.experiment.runner import COLUMNS, Settings, nh_random_variants, prepare
from search.stats import bootstrap_mean, holm, mcnemar_exact, signed_rank_exact, units_for_power
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
    assert "| CF H (simulated user) | " in table and "| Baseline H (simulated user) | " in table
    assert "CF H's success columns equal Oracle's in " in table
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
    base = [choose("baseline_h", seed=s, baseline_h="fixed", **kw) for s in range(n)]
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


def _runs(cf: dict[int, list[float]], base: dict[int, list[float]], budgets=(5, 10)):
    """q2 rows for one world and shift: per seed, CF H's and Baseline H's success by budget."""
    return [
        {
            "world": "nav2d",
            "shift": "object",
            "condition": c,
            "budget": str(b),
            "seed": str(s),
            "success": str(v),
        }
        for c, curves in (("cf_h", cf), ("baseline_h", base))
        for s, curve in curves.items()
        for b, v in zip(budgets, curve, strict=True)
    ]


def test_cf_h_against_baseline_h_has_one_unit_per_seed():
    # 5 seeds x 2 budgets, CF H ahead in every run: 5 units, not 10, so p = 1/2^5
    rows = _runs({s: [0.9, 1.0] for s in range(5)}, {s: [0.4, 0.5] for s in range(5)})
    c = seed_test.compare(rows, "nav2d", "object")
    assert c.seeds == (0, 1, 2, 3, 4) and c.test.n == 5
    assert c.test.p == 1 / 32 and c.mean_diff == pytest.approx(0.5)
    assert c.interval == pytest.approx((0.5, 0.5)), "equal differences: no spread to resample"
    text = "\n".join(seed_test.markdown(rows, [("nav2d", "object")]))
    assert "| nav2d, object | 5 | +0.50 [+0.50, +0.50] | 5 / 0 / 0 | 0.0312 (0.0312) |" in text
    assert "too few seeds to test: 5 differ" in text and "significant" not in text
    assert "5 can give p as low as 1/2^5 = 0.0312" in text, "1/32 is under 0.05/1"
    assert text.endswith("| 10 |"), "5 seeds would pass 0.05 (1/32), but 10 must differ"
    three = _runs({s: [0.9, 1.0] for s in range(3)}, {s: [0.4, 0.5] for s in range(3)})
    text = "\n".join(seed_test.markdown(three, [("nav2d", "object")]))
    assert "3 cannot give p below 1/2^3 = 0.125" in text


def test_enough_seeds_are_tested_and_ties_are_not_counted():
    ahead = {s: [1.0, 1.0] for s in range(12)}
    behind = {s: [0.0, 0.0] for s in range(12)}
    behind[11] = [1.0, 1.0]  # a tie: dropped, 11 seeds differ
    rows = _runs(ahead, behind)
    c = seed_test.compare(rows, "nav2d", "object")
    assert (c.test.n, c.test.positive, c.test.p) == (11, 11, 0.5**11)
    text = "\n".join(seed_test.markdown(rows, [("nav2d", "object")]))
    assert "11 / 0 / 1" in text and "CF H > Baseline H at 0.05 after Holm over 1 rows" in text


def test_a_row_where_no_seed_differs_is_not_tested():
    same = _runs({s: [0.5, 1.0] for s in range(5)}, {s: [0.5, 1.0] for s in range(5)})
    c = seed_test.compare(same, "nav2d", "object")
    assert c.test.n == 0 and c.test.p == 1.0 and not c.tested
    text = "\n".join(seed_test.markdown(same, [("nav2d", "object")]))
    assert "no seed differs: nothing to test" in text


def test_area_under_the_curve_is_the_trapezoid_over_the_budget_range():
    assert seed_test.area({5: 0.0, 10: 1.0, 100: 1.0}) == pytest.approx(92.5 / 95)
    assert seed_test.area({25: 0.4}) == 0.4
    assert seed_test.area({5: 0.2, 10: 0.2, 50: 0.2}) == pytest.approx(0.2)


def test_cf_h_runs_that_are_oracle_runs_are_counted():
    def run(condition, seed, success, loss):
        return {
            "world": "nav2d",
            "shift": "object",
            "condition": condition,
            "budget": "5",
            "seed": str(seed),
            "success": success,
            "success_before": "0.2",
            "success_all": success,
            "success_all_before": "0.5",
            "final_loss": loss,
        }

    rows = [
        *(run("oracle", s, "0.9", "0.01") for s in range(4)),
        run("cf_h", 0, "0.9", "0.01"),  # Oracle's run
        run("cf_h", 1, "0.9", "0.02"),  # another concept, the same success
        run("cf_h", 2, "0.4", "0.03"),
        run("cf_h", 7, "0.9", "0.01"),  # no Oracle run to compare with
    ]
    assert same_as_oracle(rows) == (2, 1, 3)
    assert same_as_oracle(rows[:4]) is None
    assert condition_label("cf_h") == "CF H (simulated user)"
    assert condition_label("oracle") == "Oracle" and condition_label("nh_random") == "NH-random"


def test_exact_signed_rank_by_hand():
    assert signed_rank_exact([0.1, 0.2, 0.3, 0.4, 0.5]).p == 1 / 32
    assert signed_rank_exact([-0.1, -0.2, -0.3, -0.4, -0.5]).p == 1.0
    # zeros dropped: 3 differences left, p = 1/8
    zeros = signed_rank_exact([0.1, 0.0, 0.1, 0.0, 0.1])
    assert (zeros.n, zeros.positive, zeros.p, zeros.p_min) == (3, 3, 1 / 8, 1 / 8)
    # float noise is not a difference: 0.3 - 0.2 ties with 0.1, 0.7 - 0.6 - 0.1 is zero
    assert signed_rank_exact([0.3 - 0.2, 0.1, 0.7 - 0.6 - 0.1]).n == 2
    # ties: |d| = 1, 1, 2, 2, 3 -> mid-ranks 1.5, 1.5, 3.5, 3.5, 5; the -1 leaves T+ = 13.5 of
    # 15, and of the 32 sign choices only those whose negative ranks sum to <= 1.5 reach it
    # (none, or either 1.5): p = 3/32
    tied = signed_rank_exact([1, -1, 2, 2, 3])
    assert (tied.n, tied.positive, tied.statistic, tied.p) == (5, 4, 13.5, 3 / 32)
    # without ties it is scipy's exact test
    d = [3, -1, 2, 5, 4, -6, 7]
    assert signed_rank_exact(d).p == pytest.approx(
        wilcoxon(d, alternative="greater", method="exact").pvalue, abs=1e-12
    )
    assert signed_rank_exact(d).p == 19 / 128
    assert signed_rank_exact([]).p == 1.0


def test_exact_mcnemar_by_hand():
    before = [True, True, False, False, False, False, False]
    after = [True, False, True, True, True, False, False]
    ch = mcnemar_exact(before, after)
    # 3 newly solved, 1 newly failed: P(Binomial(4, 1/2) >= 3) = 5/16
    assert (ch.units, ch.fixed, ch.broken, ch.p) == (7, 3, 1, 5 / 16)
    assert ch.p == pytest.approx(binomtest(3, 4, 0.5, alternative="greater").pvalue, abs=1e-12)
    assert mcnemar_exact([False] * 13, [True] * 13).p == 0.5**13
    assert mcnemar_exact(after, before).p == 15 / 16  # the same tasks the other way
    assert mcnemar_exact([True, False], [True, False]).p == 1.0  # nothing changed


def test_holm_on_known_p_values():
    assert holm([0.01, 0.04, 0.03, 0.2]) == pytest.approx([0.04, 0.09, 0.09, 0.2])
    assert holm([1 / 32] * 6) == pytest.approx([6 / 32] * 6)
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])
    assert holm([]) == []


def test_bootstrap_interval_is_seeded_and_brackets_the_mean():
    v = [0.1, 0.4, 0.7, 0.2, 0.9]
    low, high = bootstrap_mean(v, seed=3)
    assert (low, high) == bootstrap_mean(v, seed=3)
    assert 0.1 < low < np.mean(v) < high < 0.9
    assert bootstrap_mean([0.3]) == (0.3, 0.3)


def test_seeds_needed_for_power():
    # every seed ahead: p = 1/2^n, and 1/2^7 is the first at or below 0.05/6
    assert units_for_power([0.5, 0.6, 0.7, 0.6, 0.5], alpha=0.05 / 6) == 7
    assert units_for_power([0.5] * 5, alpha=0.05) == 5
    assert units_for_power([0.5] * 5, alpha=0.05, min_nonzero=10) == 10
    # two of five seeds differ: more seeds are needed to draw 7 that differ 80% of the time
    assert units_for_power([0.1, 0, 0.1, 0, 0], alpha=0.05 / 6) > 14
    assert units_for_power([0.0, -0.1], alpha=0.05) is None


def test_confidence_interval():
    one = summarise([0.5])
    assert one.n == 1 and np.isnan(one.half_width) and one.low == one.high == 0.5
    cell = summarise([0.2, 0.4, 0.6, 0.8, 1.0])
    assert cell.mean == pytest.approx(0.6)
    assert cell.half_width == pytest.approx(
        2.776 * np.std([0.2, 0.4, 0.6, 0.8, 1.0], ddof=1) / 5**0.5
    )
    assert summarise([1.0, 1.0]).high == 1.0
