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
