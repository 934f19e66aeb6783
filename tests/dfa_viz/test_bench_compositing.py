"""The tabletop rows of `dfa bench` that compare composited frames, MuJoCo frames and the
naive loop against the forward-pass bound, on a small search (singles only)."""

import re

import pytest

from dfa_viz.bench.compositing import bench_other, compositing_rows
from policy import base_policy
from sim import get_world


@pytest.mark.slow
def test_compositing_rows_are_ratios_measured_in_the_same_run():
    world = get_world("tabletop")
    r = bench_other(world, base_policy(world), repeats=1, max_size=1)  # asserts agreement
    assert world.compositing  # put back after the MuJoCo runs
    assert r["all"] == r["singles"] > 0 and r["views_drawn"] > 0
    for k, modes in (("singles", ("cold", "warm", "mujoco")), ("all", ("cold", "stored", "warm"))):
        assert r[f"{k}_bound_s"] > 0
        for how in modes:
            assert r[f"{k}_{how}_s"] > 0 and r[f"{k}_{how}_to_bound"] > 0
    assert r["naive_ratio"] == r["naive_per_candidate_s"] / (r["all_stored_s"] / r["all"])
    rows = compositing_rows(r)
    assert len(rows) == 5 and all("`other`" in what or "vs" in what for what, *_ in rows)
    for what, value, target, met in rows:
        assert re.fullmatch(r"[0-9.]+ ?(x|s)", value), (what, value)
        assert (target == "") == (met is None)
