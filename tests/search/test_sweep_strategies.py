"""Searches of the sweep's edit space replayed on outcome tables: small tables built by hand
with their answers worked out by hand, the seeded searches reproducible, and one real nav2d
comparison through `dfa experiment search`."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dfa_viz.cli import main
from policy import base_policy
from search.sweep import plan, run_unit, summarise, sweep_tasks
from search.sweep.compare import compare
from search.sweep.strategies import (
    STOCHASTIC,
    STRATEGIES,
    exhaustive,
    prior_order,
    reinforce,
    surrogate,
    uniform,
)
from search.sweep.table import OutcomeTable, Trial, agrees, outcome_table, trace
from sim import get_world


def table(fails: list[list[bool]], control=None, counted=None) -> OutcomeTable:
    """A table of arms x tasks (one place each), fails[arm][task], in the sweep's order (task
    by task, arms in order); modes by the table's own test."""
    arms, tasks = len(fails), len(fails[0])
    trials = tuple(Trial(a, t, 0, False) for t in range(tasks) for a in range(arms))
    failed = np.array([fails[tr.arm][tr.task] for tr in trials], bool)
    ok = np.ones(len(trials), bool) if counted is None else np.array(counted, bool)
    ctrl = np.zeros(tasks, bool) if control is None else np.array(control, bool)
    keys = tuple(("obj", "colour", f"v{a}") for a in range(arms))
    t = OutcomeTable("made", keys, trials, failed, ok, ctrl, frozenset())
    by_arm = [[i for i, tr in enumerate(trials) if tr.arm == a] for a in range(arms)]
    modes = frozenset(a for a in range(arms) if t.confirms(by_arm[a]))
    return OutcomeTable("made", keys, trials, failed, ok, ctrl, modes)


T, F = True, False
SMALL = [[T, T, T, T], [T, T, T, F], [F, F, F, T]]  # arm 2 fails once: no mode


def test_one_failure_is_no_mode_two_are():
    t = table(SMALL)
    assert t.modes == {0, 1}
    assert not t.confirms([0]) and t.confirms([0, 3])  # arm 0 on tasks 0 and 1
    assert t.rollouts == 12 + 4


def test_the_sweeps_order_finds_modes_at_counts_worked_out_by_hand():
    """Task 0: control (1), arms 0-2 (2-4); task 1: control (5), arm 0 (6: its second failure,
    confirmed), arm 1 (7: confirmed)."""
    tr = trace(table(SMALL), exhaustive(table(SMALL)))
    assert (tr.rollouts_to(1), tr.rollouts_to(2), tr.rollouts_to(3)) == (6, 7, None)
    assert tr.found_by(5) == 0 and tr.found_by(6) == 1 and tr.found_by(100) == 2
    assert len(tr.found) == 16 and tr.false_alarms == 0


def test_a_given_order_pays_each_control_once():
    """Arm 1 on tasks 3, 2, 1, 0: a control for each (2 rollouts per task). Passed once and
    failed twice is not enough (Newcombe's low end -0.06); the third failure confirms it
    (+0.09), at rollout 8."""
    t = table(SMALL)
    tr = trace(t, [3 * 3 + 1, 2 * 3 + 1, 1 * 3 + 1, 0 * 3 + 1])
    assert tr.found.tolist() == [0] * 7 + [1]


def test_failures_the_control_shares_or_the_expert_rules_out_do_not_count():
    t = table(SMALL, control=[T, F, F, F])  # task 0 fails unedited: arm 0's and 1's are shared
    assert not t.hit(0) and t.hit(3)
    assert t.counts([0, 3]) == (1, 1, 0, 0)
    uncounted = table(SMALL, counted=[i % 3 != 0 for i in range(12)])  # arm 0 never counted
    assert uncounted.modes == {1} and not uncounted.confirms([0, 3, 6, 9])


def test_a_search_that_confirms_a_chance_failure_counts_a_false_alarm():
    """Arm 0 fails on tasks 0 and 1 of 12: confirmed on those two alone, not on all twelve."""
    fails = [[T, T] + [F] * 10]
    t = table(fails)
    assert t.modes == frozenset()
    assert trace(t, exhaustive(t)).false_alarms == 1


def big(seed: int = 0) -> OutcomeTable:
    """20 edits on 10 tasks: edits 3, 11 and 17 fail everywhere, the rest once in 10."""
    rng = np.random.default_rng(seed)
    fails = (rng.random((20, 10)) < 0.1).tolist()
    for a in (3, 11, 17):
        fails[a] = [True] * 10
    return table(fails)


@pytest.mark.parametrize("search", [uniform, surrogate, reinforce])
def test_seeded_searches_are_reproducible_and_ask_each_trial_once(search):
    t = big()
    a, b, c = search(t, 4), search(t, 4), search(t, 5)
    assert a == b and a != c
    assert len(set(a)) == len(a) and set(a) <= set(range(len(t.trials)))
    assert trace(t, a).rollouts_to(len(t.modes)) is not None  # every mode confirmed


def test_adaptive_searches_find_the_modes_sooner_than_uniform_sampling():
    t = big()
    assert t.modes == {3, 11, 17}
    runs = {r.name: r for r in compare(t, STRATEGIES, seeds=6, stochastic=STOCHASTIC)}
    every = runs["uniform"].to[-1].mean
    assert runs["surrogate"].to[-1].mean < 0.6 * every, (runs["surrogate"].to, every)
    assert runs["reinforce"].to[-1].mean < 0.9 * every, (runs["reinforce"].to, every)
    # adaptive searches drop a confirmed edit: they never reach the end of the table
    assert len(surrogate(t, 0)) < len(t.trials) and len(reinforce(t, 0)) < len(t.trials)
    assert runs["exhaustive"].seeds == 1 and runs["uniform"].seeds == 6


def test_the_priors_order_is_its_costs_lowest_first_ties_in_the_sweeps_order():
    t = table(SMALL)
    costs = np.array([2.0, 1.0, 3.0] * 4)
    assert prior_order(costs)(t, 0) == [1, 4, 7, 10, 0, 3, 6, 9, 2, 5, 8, 11]


def test_the_nav2d_table_is_the_sweeps_own():
    world = get_world("nav2d")
    p = plan(sweep_tasks(world, 12))
    results = [run_unit(world, base_policy(world), u) for u in p.units(world)]
    t = outcome_table(world, p, results)
    result = summarise(world, p, results, policy="base")
    assert agrees(t, result) and t.modes
    assert len(t.trials) == sum(c.applies for c in result.cells)
    assert trace(t, exhaustive(t)).rollouts_to(len(t.modes)) <= t.rollouts


def test_dfa_experiment_search_on_nav2d(tmp_path, capsys):
    out = tmp_path / "cmp"
    args = ["experiment", "search", "--world", "nav2d", "--tasks", "12", "--seeds", "3"]
    assert main([*args, "--prior-tasks", "2", "--out", str(out), "--no-progress"]) == 0
    record = json.loads((out / "nav2d.json").read_text())
    names = [r["name"] for r in record["runs"]]
    assert names == ["exhaustive", "uniform", "surrogate", "reinforce", "prior"]
    assert record["modes"] and all(
        r["to"][-1]["mean"] <= record["rollouts"] for r in record["runs"]
    )
    text = (out / "table.md").read_text()
    assert "REINFORCE over edits" in text and record["command"] in text
    assert (out / "modes.png").read_bytes()[:4] == b"\x89PNG"
    assert "failure modes" in capsys.readouterr().out
    assert main([*args[:4], "--seeds", "0", "--out", str(out)]) == 2
