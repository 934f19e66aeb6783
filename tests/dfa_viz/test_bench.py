import re

from dfa_viz.bench.costs import cost_rows, render_throughput


def test_render_throughput_compares_like_with_like():
    r = render_throughput("nav2d", n=16, repeats=1)
    assert r["n"] == 16 and r["batched_fps"] > 0 and r["single_fps"] > 0
    assert abs(r["ratio"] - r["batched_fps"] / r["single_fps"]) < 1e-9


def test_cost_rows_name_every_figure(nav_policy, tmp_path):
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"\0" * 2**20)
    rows = cost_rows("nav2d", 1.5, rrd, repeats=1)
    values = {what.split(" (")[0]: value for what, value, _, _ in rows}
    assert set(values) == {
        "nav2d: render throughput, one batch of 64 scenes vs one scene at a time",
        "nav2d: finetune, 300 steps of 64 samples, half replayed",
        "nav2d: recording of one `dfa run`",
        "nav2d: one `dfa experiment q2` run",
    }
    assert values["nav2d: recording of one `dfa run`"] == "1.00 MiB"
    for value in values.values():
        assert re.fullmatch(r"[0-9.]+ ?(x|s|MiB)", value), value


def test_a_minigrid_search_with_an_outside_policy_is_timed_against_naive_and_the_bound():
    """The MiniGrid row of `dfa bench`: the stable-baselines3 agent of docs/examples; the
    naive and lockstep searches must agree (bench_world asserts it), and the forward-pass
    bound counts only the candidate-steps the search evaluated."""
    from dfa_viz.bench.run import MINIGRID, OUTSIDE_POLICIES, run_bench  # noqa: F401
    from dfa_viz.bench.search import bench_world

    r = bench_world(MINIGRID, repeats=1, shift="distractor_ti", policy=OUTSIDE_POLICIES[MINIGRID])
    assert r["candidates"] == sum(r["per_size"].values()) > 0
    from sim import get_world

    assert r["candidates"] <= r["evaluated"] <= r["candidates"] * get_world(MINIGRID).horizon
    assert r["bound_s"] > 0 and r["to_bound"] == r["batched_s"] / r["bound_s"]


def test_short_figures_are_timed_over_at_least_min_s():
    import time

    from dfa_viz.bench.timing import MAX_RUNS, best_of

    runs = []

    def work():
        runs.append(1)
        time.sleep(0.001)
        return len(runs)

    best, last = best_of(work, 3)
    assert len(runs) == last == 3 and best >= 0.001
    runs.clear()
    best, last = best_of(work, 3, min_s=0.03)
    assert 10 <= len(runs) == last <= 31 and 0.001 <= best < 0.03
    runs.clear()
    best_of(lambda: runs.append(1), 1, min_s=60.0)
    assert len(runs) == MAX_RUNS
