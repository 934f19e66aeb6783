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
    """best_of's rule, checked by what it must do whatever the machine's load: `repeats` runs,
    more while the runs so far took under min_s, never more than MAX_RUNS. Each run sleeps at
    least 1 ms, and the test's own clock around a run holds best_of's clock around it."""
    import time

    from dfa_viz.bench.timing import MAX_RUNS, best_of

    took: list[float] = []  # each run, timed inside it (never longer than best_of's timing)

    def work():
        t0 = time.perf_counter()
        time.sleep(0.001)
        took.append(time.perf_counter() - t0)
        return len(took)

    best, last = best_of(work, 3)
    assert len(took) == last == 3 and best >= min(took) >= 0.001

    took.clear()
    t0 = time.perf_counter()
    best, last = best_of(work, 3, min_s=0.03)
    spent = time.perf_counter() - t0
    assert last == len(took) >= 3
    assert spent >= 0.03  # not done before min_s had passed
    assert len(took) == 3 or sum(took[:-1]) < 0.03  # no run after min_s was reached
    assert len(took) <= 31  # 30 runs of 1 ms or more reach 0.03 s
    assert min(took) <= best <= spent / len(took)  # the best run, not the mean or the sum

    took.clear()
    best_of(lambda: took.append(1), 1, min_s=float("inf"))
    assert len(took) == MAX_RUNS
