"""The tabletop rows of `dfa bench` that compare composited frames, MuJoCo frames and the
naive loop against the forward-pass bound, on a small search (singles only); the bench's
planted double shifts searched with either renderer."""

import re

import numpy as np
import pytest

from dfa_viz.bench.compositing import bench_other, compositing_rows
from dfa_viz.bench.tabletop import PLANTED, planted_shift
from policy import base_policy
from search import SearchConfig, counterfactual_search
from sim import get_world
from sim.tabletop.world import TabletopWorld


@pytest.fixture(scope="module")
def mujoco_world():
    return TabletopWorld(compositing=False)


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


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_planted_double_shift_gives_the_same_pair_with_either_renderer(mujoco_world, seed):
    """The bench's planted pairs: composited frames find what MuJoCo's frames find."""
    world = get_world("tabletop")
    policy = base_policy(world)
    config = SearchConfig.for_world(world)
    task, demo, got = planted_shift(world, policy, seed, 2, config)
    train = world.train_task(task.seed)
    looks = [(s.name, c.name) for s in world.space.slots for c in s.concepts]
    changed = [
        (s, c) for s, c in looks if train.scene.obj(s).value(c) != task.scene.obj(s).value(c)
    ]
    assert set(changed) == set(PLANTED[2]) and task.cause == PLANTED[2][0]
    want = counterfactual_search(mujoco_world, policy, task.scene, demo, config=config)
    assert got.size == 2, got.summary()
    assert [c.edit for c in got.counterfactuals] == [c.edit for c in want.counterfactuals]
    assert [c.edit for c in got.tried] == [c.edit for c in want.tried]
    for a, b in zip(got.tried, want.tried, strict=True):
        assert np.array_equal(a.distances, b.distances, equal_nan=True), a.edit
