"""`dfa bench`: every speed figure, measured on this machine, written to benchmarks/latest.md."""

from __future__ import annotations

import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from dfa_viz.bench.prior import bench_prior, prior_rows
from dfa_viz.bench.search import bench_world
from dfa_viz.bench.sweep import SWEPT, sweep_rows
from dfa_viz.bench.timing import machine
from dfa_viz.configs import BenchArgs
from policy import base_policy
from sim import PAPER_WORLDS, get_world
from sim.core import files


def bench_run(
    name: str, shift: str = "object_ti", seed: int = 0, policy: str | None = None
) -> float:
    """Wall time of a whole `dfa run` in this process, base policy already cached."""
    from dfa_viz.assemble import RunArgs, run_once

    if policy is None:
        base_policy(get_world(name))  # loaded and checked once before the clock starts
    t0 = time.perf_counter()
    out = Path("recordings") / "bench"
    run_once(RunArgs(world=name, shift=shift, seed=seed, out=out, policy=policy), progress=False)
    return time.perf_counter() - t0


# world -> the sizes whose whole search has a time target (the issues' targets, 2 cores)
TIME_TARGETS = {"nav2d": ((1, 2), 0.5), "doorkey": ((1,), 0.5)}
# worlds measured with a policy from outside instead of a base policy of the project's own
MINIGRID = "minigrid:MiniGrid-DoorKey-5x5-v0:tile=12"
OUTSIDE_POLICIES = {MINIGRID: "sb3:docs/examples/doorkey5x5_ppo.zip"}
MIN_RATIO = 10.0
MAX_TO_BOUND = 2.0  # every search within 2x of its forward-pass bound (dfa_viz.bench.bound)
PAGE_TARGETS = {
    "page_load_to_interactive_s": 3.0,
    "slider_to_images_ms_median": 100.0,
    "nav2d_finetune_round_trip_s": 30.0,
}


def run_bench(args: BenchArgs) -> list[tuple[str, str, str, str]]:
    """Measure, print a table, and write it as Markdown to `args.out`.

    Rows are (what, value, target, met). The page figures need Chromium and take a minute or
    two; they are measured when `args.page` is set.
    """
    worlds, repeats, page, out = args.worlds, args.repeats, args.page, args.out
    rows: list[tuple[str, str, str, str]] = []

    def add(what: str, value: str, target: str = "", ok: bool | None = None) -> None:
        rows.append((what, value, target, "" if ok is None else ("yes" if ok else "NO")))

    def costs(name: str, run_s: float) -> None:
        from dfa_viz.bench.costs import cost_rows

        rrd = Path("recordings") / "bench" / files.safe_name(f"{name}-object_ti-seed0.rrd")
        for row in cost_rows(name, run_s, rrd, repeats=repeats):
            add(*row)

    for name in worlds:
        if name in SWEPT:
            for row in sweep_rows(name):
                add(*row)
        if name in PAPER_WORLDS:  # the learned search prior on planted size-2 tasks
            for row in prior_rows(bench_prior(name, n_eval=args.prior_tasks)):
                add(*row)
        if name == "tabletop":
            from dfa_viz.bench.tabletop import bench_rows, bench_tabletop

            for what, value, target, ok in bench_rows(bench_tabletop(repeats=repeats)):
                add(f"tabletop: {what}", value, target, ok)
            costs(name, bench_run(name))
            continue
        spec = OUTSIDE_POLICIES.get(name)
        shown = name if spec is None else f"{name} ({spec.partition(':')[0]} policy)"
        if name in TIME_TARGETS:
            sizes, max_s = TIME_TARGETS[name]
            label = " + ".join(f"size {k}" for k in sizes)
            # `other` has no counterfactual: the search really runs every size to the end
            r = bench_world(name, repeats=repeats, shift="other", sizes=sizes, policy=spec)
            add(
                f"{shown}: whole {label} search, no counterfactual ({r['candidates']} edits)",
                f"{r['batched_s'] * 1000:.1f} ms",
                f"< {max_s * 1000:.0f} ms",
                r["batched_s"] < max_s,
            )
        for shift in ("other", "distractor_ti"):
            r = bench_world(name, repeats=repeats, shift=shift, sizes=(1, 2), policy=spec)
            add(
                f"{shown}: size 1 + 2 search on {shift}, batched vs naive one-at-a-time loop "
                f"({r['candidates']} edits: {r['batched_s'] * 1000:.1f} vs "
                f"{r['naive_s'] * 1000:.1f} ms; {r['per_s']:.0f} candidates/s)",
                f"{r['ratio']:.1f}x",
                f">= {MIN_RATIO:.0f}x",
                r["ratio"] >= MIN_RATIO,
            )
            add(
                f"{shown}: the same search vs its forward-pass bound ({r['evaluated']} "
                f"candidate-steps at {r['forward_per_s']:.0f} frames/s through the policy: "
                f"{r['bound_s'] * 1000:.1f} ms over {r['passes']} batched passes)",
                f"{r['to_bound']:.2f}x",
                f"<= {MAX_TO_BOUND:.0f}x",
                r["to_bound"] <= MAX_TO_BOUND,
            )
        run_s = bench_run(name, policy=spec)
        add(
            f"{shown}: `dfa run` end to end, policy loaded",
            f"{run_s:.1f} s",
            "< 30 s",
            run_s < 30,
        )
        if spec is None:  # the costs of finetuning and the experiment: the project's own policies
            costs(name, run_s)
    if page:
        from dfa_viz.bench.page import bench_page

        for key, value in bench_page().items():
            shown = f"{value:.3g}" if isinstance(value, float) else str(value)
            if key in PAGE_TARGETS:
                limit = PAGE_TARGETS[key]
                add(f"page: {key}", shown, f"<= {limit:g}", float(value) <= limit)
            else:
                add(f"page: {key}", shown)
    console = Console()
    table = Table(title=f"dfa bench — {machine()}")
    for col in ("figure", "value", "target", "met"):
        table.add_column(col)
    for row in rows:
        table.add_row(*row)
    console.print(table)
    out.parent.mkdir(parents=True, exist_ok=True)
    md = [
        f"# dfa bench\n\nMachine: {machine()}\n",
        "| figure | value | target | met |",
        "|---|---|---|---|",
    ]
    md += [f"| {' | '.join(r)} |" for r in rows]
    files.write_text(out, "\n".join(md) + "\n")
    console.print(f"written to {out}")
    return rows
