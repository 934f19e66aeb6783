"""`dfa experiment explain`: the explainers against the planted causes, end to end and in parts."""

import csv

import pytest

from dfa_viz.cli import main
from dfa_viz.experiment.explain import (
    COLUMNS,
    EXPLAINERS,
    MASK_COLUMNS,
    READINGS,
    SPANS,
    ExplainSettings,
    TaskSpec,
    explain_task,
    explainer_names,
    readouts_of,
)
from dfa_viz.experiment.explain_figures import write_plot
from dfa_viz.experiment.explain_results import (
    cell,
    explain_folder,
    markdown_table,
    rates,
    readout_rows,
)
from dfa_viz.experiment.explain_run import ExplainPlan, run_explain
from sim.core import UserError

PLAN = ExplainPlan(worlds=("nav2d",), shifts=("object_ti", "distractor_ti"), tasks=2)
FAST = ("counterfactual", "integrated_gradients", "grad_cam", "kernel_shap", "random")
SETTINGS = ExplainSettings(
    explainers=FAST, saliency={"ig_steps": 8, "shap_samples": 16}, sanity_steps=2
)


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def benchmark(tmp_path_factory):
    out = tmp_path_factory.mktemp("explain")
    summary = run_explain(PLAN, out=out, settings=SETTINGS, workers=1, progress=False)
    return summary


def test_a_tiny_benchmark_writes_the_table_the_plot_and_every_row(benchmark):
    out = benchmark.out
    assert (benchmark.planned, benchmark.skipped, benchmark.executed) == (4, 0, 4)
    rows = _rows(out / "tasks.csv")
    assert len(rows) == 4 * (2 + 3 * 4) and tuple(rows[0]) == COLUMNS  # 4 readouts per map
    assert {r["cause"] for r in rows} == {"goal.colour", "goal.shape", "distractor.presence"}
    for r in rows:
        ranked = r["ranking"].split()
        assert len(ranked) == int(r["n_concepts"]) and r["cause"] in ranked
        assert int(r["rank"]) == ranked.index(r["cause"]) + 1
    cf = [r for r in rows if r["explainer"] == "counterfactual"]
    assert all(r["hit1"] == "1" for r in cf)  # nav2d's planted causes are all found
    for r in rows:  # the steps before divergence are some of all the steps
        if r["explainer"] in ("counterfactual", "random"):
            assert (r["reading"], r["span"], r["n_steps"]) == ("-", "-", "-")
        else:
            mate = next(
                o
                for o in rows
                if o["span"] == "all"
                and o["explainer"] == r["explainer"]
                and (o["shift"], o["seed"]) == (r["shift"], r["seed"])
            )
            assert 1 <= int(r["n_steps"]) <= int(mate["n_steps"])
    for r in rows:  # the checks against the mask: shares, a deletion score, 5 correlations
        if r["explainer"] == "counterfactual":
            assert all(r[c] == "-" for c in MASK_COLUMNS), r
        elif r["explainer"] == "random":
            assert float(r["deletion"]) > 0 and r["mass_cause"] == "-", r
        else:
            assert 0 < float(r["area_cause"]) < 0.1, r  # nav2d's objects are small
            shares = [float(r[c]) for c in ("mass_cause", "mass_off")]  # nan: no mass to share
            assert all(0 <= x <= 1 or (x != x and r["reading"] == "signed") for x in shares), r
            rho = [float(x) for x in r["randomised"].split()]
            assert len(rho) == 5 and all(-1 <= x <= 1 for x in rho), r
    table = (out / "table.md").read_text()
    assert "## Against the ground-truth mask" in table
    assert "Object top-1 hits (%), |attribution|, all steps" in table
    assert "Top-1 hits (%), signed, steps before the rollout diverges" in table
    assert "97 / 28" in table and "Time per task" in table
    assert (out / "hits.png").read_bytes()[:4] == b"\x89PNG"
    assert len(_rows(out / "timings.csv")) == 4 * len(FAST)  # one per explainer and task


def test_it_resumes_and_a_cut_line_is_run_again(benchmark, tmp_path):
    out = tmp_path / "again"
    out.mkdir()
    for name in ("config.json", "tasks.csv", "timings.csv"):
        (out / name).write_bytes((benchmark.out / name).read_bytes())
    text = (out / "tasks.csv").read_text()
    (out / "tasks.csv").write_text(text[: text.rstrip("\n").rfind("\n") + 1] + "nav2d,dis")
    again = run_explain(PLAN, out=out, settings=SETTINGS, workers=1, progress=False)
    assert (again.skipped, again.executed) == (3, 1)
    assert _rows(out / "tasks.csv") == _rows(benchmark.out / "tasks.csv")  # the same rows


def test_a_task_is_a_pure_function_of_its_spec():
    spec = TaskSpec("nav2d", "distractor_tr", 1)
    settings = ExplainSettings(explainers=("counterfactual", "kernel_shap", "random"))
    assert explain_task(spec, settings)["rows"] == explain_task(spec, settings)["rows"]


def test_other_settings_do_not_mix_into_a_folder(benchmark):
    with pytest.raises(UserError, match="another --out"):
        explain_folder(benchmark.out, ExplainSettings(explainers=("random",)))


ONE = {"reading": "-", "span": "-"}


def test_rates_are_written_with_wilson_intervals():
    assert cell(47, 50) == "94 (84–98)"
    assert cell(0, 50) == "0 (0–7)"
    assert cell(0, 0) == "—"
    row = dict.fromkeys(COLUMNS, "0") | {"world": "nav2d", "shift": "object_ti"}
    text = markdown_table([row | ONE | {"explainer": "random"}], [], ExplainSettings())
    assert "| nav2d | object_ti | 1 | 0 (0–79) | 97 / 28 |" in text


def test_rates_count_distinct_tasks_once():
    row = dict.fromkeys(COLUMNS, "0") | ONE | {"world": "nav2d", "explainer": "random"}
    # 47 seeds draw task a (a hit), three draw b, c, d (misses); TR repeats TI's tasks
    rows = [
        row
        | {"shift": shift, "seed": str(s), "task_id": "a" if s < 47 else "bcd"[s - 47]}
        | ({"object_hit1": "1"} if s < 47 else {})
        for shift in ("object_ti", "object_tr")
        for s in range(50)
    ]
    table = rates(rows, "object_hit1")
    assert table[("nav2d", "object_ti", "random")] == (1.0, 4)  # 1 of 4 tasks, not 47 of 50
    assert table[("nav2d", "all", "random")] == (1.0, 4)  # TI and TR tasks are the same four
    assert cell(*table[("all", "all", "random")]) == "25 (5–70)"
    text = markdown_table(rows, [], ExplainSettings())
    assert "| nav2d | object_ti | 4 | 25 (5–70) |" in text
    mixed = [*rows[:2], rows[2] | {"task_id": "a", "object_hit1": "0"}]  # a task hit 2 of 3
    assert rates(mixed, "object_hit1")[("nav2d", "object_ti", "random")] == (2 / 3, 1)


def test_each_readout_is_tabled_apart_beside_the_one_reading_explainers():
    row = dict.fromkeys(COLUMNS, "0") | {"world": "nav2d", "shift": "distractor_ti"}
    rows = [row | ONE | {"explainer": "counterfactual", "object_hit1": "1"}]
    for reading in READINGS:
        for span in SPANS:
            hit = str(int(reading == "signed"))
            rows.append(
                row
                | {"explainer": "occlusion", "reading": reading, "span": span}
                | {"object_hit1": hit}
            )
    signed = rates(readout_rows(rows, ("signed", "before")), "object_hit1")
    unsigned = rates(readout_rows(rows, ("abs", "all")), "object_hit1")
    assert signed[("nav2d", "distractor_ti", "occlusion")] == (1.0, 1)
    assert unsigned[("nav2d", "distractor_ti", "occlusion")] == (0.0, 1)
    assert signed[("nav2d", "distractor_ti", "counterfactual")] == (1.0, 1)
    assert readouts_of("occlusion") == tuple((r, s) for r in READINGS for s in SPANS)
    assert readouts_of("counterfactual") == (("-", "-"),)


def test_the_readouts_are_policy_s_own():
    from policy import concept_saliency

    assert (READINGS, SPANS) == (concept_saliency.READINGS, concept_saliency.SPANS)


def test_the_plot_draws_rates_of_none_and_of_all(tmp_path):
    row = dict.fromkeys(COLUMNS, "0") | {"world": "doorkey", "shift": "distractor_tr"}
    row |= {"reading": "abs", "span": "all"}
    rows = [
        row | {"explainer": "kernel_shap", "seed": str(s), "task_id": str(s)} for s in range(50)
    ]
    hit = {"hit1": "1", "hit3": "1", "object_hit1": "1"}
    rows += [
        row | ONE | hit | {"explainer": "counterfactual", "seed": str(s), "task_id": str(s)}
        for s in range(50)
    ]
    assert write_plot(tmp_path, rows).read_bytes()[:4] == b"\x89PNG"  # 0 of 50, 50 of 50
    table = markdown_table(rows, [], ExplainSettings())
    assert "| doorkey | distractor_tr | 50 | 100 (93–100) | 0 (0–7) | 88 / 32 |" in table


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tasks", "0"], "--tasks"),
        (["--method", "lrp"], "unknown explainer 'lrp'"),
        (["--shift", "other"], "no planted cause for shift 'other'"),
        (["--world", "atlantis"], "unknown world 'atlantis'"),
        (["--max-size", "0"], "--max-size"),
    ],
)
def test_bad_flags_are_one_line_and_exit_2(tmp_path, capsys, args, message):
    assert main(["experiment", "explain", *args, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_every_explainer_has_a_name_in_the_cli_defaults():
    from dfa_viz.experiment.args import ExplainArgs

    assert ExplainArgs().methods == EXPLAINERS


def test_the_saliency_explainers_are_policy_methods_with_their_names():
    from policy.methods import METHOD_NAMES, METHODS

    assert ("counterfactual", *METHODS, "random") == EXPLAINERS
    names = explainer_names()
    assert {m: names[m] for m in METHODS} == METHOD_NAMES
    assert set(names) == set(EXPLAINERS)


def test_a_readout_chosen_on_one_half_of_the_tasks_scores_the_other():
    from dfa_viz.experiment.explain_results import held_out

    row = dict.fromkeys(COLUMNS, "0") | {"world": "nav2d", "shift": "distractor_ti"}

    def rows(hits):  # hits(task, readout) -> 0 / 1; tasks "0" .. "3", halves by parity
        return [
            row
            | {"explainer": "occlusion", "reading": r, "span": s, "task_id": t, "seed": t}
            | {"object_hit1": str(hits(int(t), (r, s)))}
            for t in "0123"
            for r in READINGS
            for s in SPANS
        ]

    everywhere, picks = held_out(rows(lambda t, ro: int(ro == ("signed", "all"))))
    assert picks[("nav2d", "occlusion")] == [("signed", "all")] * 2
    assert rates(everywhere, "object_hit1")[("nav2d", "all", "occlusion")] == (4.0, 4)
    # each half's own best readout misses on the other half: held out, nothing is hit
    split, picks = held_out(
        rows(lambda t, ro: int(ro == (("abs", "all"), ("signed", "all"))[t % 2]))
    )
    assert picks[("nav2d", "occlusion")] == [("signed", "all"), ("abs", "all")]
    assert rates(split, "object_hit1")[("nav2d", "all", "occlusion")] == (0.0, 4)
    assert {r["reading"] for r in split} == {"chosen"}
