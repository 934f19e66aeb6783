"""`dfa bench`'s rows for the search on a MuJoCo world (dfa_viz.bench.closed_loop): Fetch
pick-and-place, whose counterfactual "succeeds" (each candidate rolled out to the end and
judged by the task's R'), on a few edits: the naive loop's verdicts are the search's, and every
figure is a finite positive ratio against a bound or baseline measured in the same run."""

from __future__ import annotations

import math
import re

import sim
from dfa_viz.bench.closed_loop import MAX_TO_BOUND, bench_closed_loop, closed_loop_rows
from policy.base import record_folder
from policy.checkpoint import load_policy
from search import singles

FETCH = "fetch:FetchPickAndPlace-v4"
FOUND = "table.colour: green -> light grey"  # object_ti seed 0's counterfactual (size 1)


def test_fetch_rows_time_the_search_against_both_bounds_and_a_naive_loop_that_agrees():
    world = sim.get_world(FETCH)
    assert world.counterfactual == "succeeds"
    policy = load_policy(record_folder(world), world=world)  # the committed base policy
    ones = [str(e) for e in singles(world.space, world.test_task("object_ti", 0).scene)]
    picked = (ones.index(FOUND), ones.index("distractor0.presence: absent -> present"))
    r = bench_closed_loop(FETCH, singles_at=picked, pairs=1, naive_sample=2, policy=policy)
    one, two = r[1], r[2]
    assert (one["edits"], two["edits"]) == (2, 1)
    assert one["valid"] == 1  # the task's counterfactual, and the distractor added is not one
    for f in (one, two):
        assert f["naive_sampled"] == f["edits"] and f["agree"] == f["edits"]  # every verdict
        steps = f["steps"] * f["edits"]  # every candidate rolled out to the end, none dropped
        assert f["evaluated"] == f["stepped"] == f["rendered"] == steps
        for key in ("to_bound", "to_forward", "to_physics", "naive_ratio"):
            assert math.isfinite(f[key]) and f[key] > 0, (key, f[key])
        assert f["to_bound"] == f["search_s"] / max(f["forward_s"], f["physics_s"])
    rows = closed_loop_rows(FETCH, r)
    assert len(rows) == 4
    for (what, value, _, _), size in zip(rows, (1, 1, 2, 2), strict=True):
        assert what.startswith(f"{FETCH}: ") and f"size-{size} search" in what
        assert re.fullmatch(r"[0-9]+\.[0-9]{2}x", value), value
    assert [r[2] for r in rows] == [f"<= {MAX_TO_BOUND:g}x", "", f"<= {MAX_TO_BOUND:g}x", ""]
    assert rows[0][3] == (one["to_bound"] <= MAX_TO_BOUND) and rows[1][3] is None
