"""`dfa bench`: every speed figure, measured on this machine, written to benchmarks/latest.md.

What each world is measured on is data (WorldBench, BENCHES); the row producers read it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from rich.console import Console
from rich.table import Table

from dfa_viz.bench.args import MINIGRID, BenchArgs
from dfa_viz.bench.closed_loop import PAIRS
from dfa_viz.bench.prior import bench_prior, prior_rows
from dfa_viz.bench.search import bench_world
from dfa_viz.bench.sweep import SWEPT, sweep_rows
from dfa_viz.bench.timing import machine
from policy import base_policy
from sim import PAPER_WORLDS, get_world
from sim.core import files

Row = tuple[str, str, str, bool | None]  # (what, value, target, met)


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


@dataclass(frozen=True)
class WorldBench:
    """What `dfa bench` measures on one world, beside its sweep (SWEPT) and, for the paper's
    worlds, its learned search prior."""

    policy: str | None = None
    """A policy from outside (a policy.outside spec) instead of the world's base policy; the
    costs of finetuning and of the experiment are measured only on the base policy."""
    whole_search: tuple[tuple[int, ...], float] | None = None
    """The sizes whose whole search, run to the end, has a time target (s) (the issues'
    targets, 2 cores)."""
    searches: bool = True
    """The batched search against the naive loop and the forward-pass bound, and `dfa run`
    end to end with a target."""
    at_scale: bool = False
    """The search at scale (dfa_viz.bench.tabletop) instead."""
    closed_loop: int | None = None
    """A world whose counterfactual "succeeds" (World.counterfactual, the MuJoCo worlds): its
    size-1 search (every single edit) and size-2 search (this many edits, the first in the
    search's order) against the larger of the forward-pass and MuJoCo bounds and against the
    naive loop (dfa_viz.bench.closed_loop), and nothing else: `dfa run` and the costs of its
    policy take minutes each there. Not among `dfa bench`'s default worlds."""


BENCHES = {
    "nav2d": WorldBench(whole_search=((1, 2), 0.5)),
    "doorkey": WorldBench(whole_search=((1,), 0.5)),
    "tabletop": WorldBench(searches=False, at_scale=True),
    MINIGRID: WorldBench(policy="sb3:docs/examples/doorkey5x5_ppo.zip"),
    "fetch:FetchPickAndPlace-v4": WorldBench(searches=False, closed_loop=PAIRS),
    "robosuite:Lift": WorldBench(searches=False, closed_loop=PAIRS),
}
OUTSIDE_POLICIES = {name: b.policy for name, b in BENCHES.items() if b.policy is not None}
MIN_RATIO = 10.0
MAX_TO_BOUND = 2.0  # every search within 2x of its forward-pass bound (dfa_viz.bench.bound)
PAGE_TARGETS = {
    "page_load_to_interactive_s": 3.0,
    "slider_to_images_ms_median": 100.0,
    "nav2d_finetune_round_trip_s": 30.0,
}


def shown(name: str, bench: WorldBench) -> str:
    """The world's name in a row, with the kind of a policy from outside."""
    return name if bench.policy is None else f"{name} ({bench.policy.partition(':')[0]} policy)"


def search_rows(name: str, bench: WorldBench, repeats: int) -> list[Row]:
    """The whole search against its target, then per shift the batched search against the
    naive loop and against its forward-pass bound."""
    spec, who = bench.policy, shown(name, bench)
    rows: list[Row] = []
    if bench.whole_search is not None:
        sizes, max_s = bench.whole_search
        label = " + ".join(f"size {k}" for k in sizes)
        # `other` has no counterfactual: the search really runs every size to the end
        r = bench_world(name, repeats=repeats, shift="other", sizes=sizes, policy=spec)
        what = f"{who}: whole {label} search, no counterfactual ({r['candidates']} edits)"
        ms = f"{r['batched_s'] * 1000:.1f} ms"
        rows.append((what, ms, f"< {max_s * 1000:.0f} ms", r["batched_s"] < max_s))
    for shift in ("other", "distractor_ti"):
        r = bench_world(name, repeats=repeats, shift=shift, sizes=(1, 2), policy=spec)
        rows.append(
            (
                f"{who}: size 1 + 2 search on {shift}, batched vs naive one-at-a-time loop "
                f"({r['candidates']} edits: {r['batched_s'] * 1000:.1f} vs "
                f"{r['naive_s'] * 1000:.1f} ms; {r['per_s']:.0f} candidates/s)",
                f"{r['ratio']:.1f}x",
                f">= {MIN_RATIO:.0f}x",
                r["ratio"] >= MIN_RATIO,
            )
        )
        rows.append(
            (
                f"{who}: the same search vs its forward-pass bound ({r['evaluated']} "
                f"candidate-steps at {r['forward_per_s']:.0f} frames/s through the policy: "
                f"{r['bound_s'] * 1000:.1f} ms over {r['passes']} batched passes)",
                f"{r['to_bound']:.2f}x",
                f"<= {MAX_TO_BOUND:.0f}x",
                r["to_bound"] <= MAX_TO_BOUND,
            )
        )
    return rows


def world_rows(name: str, args: BenchArgs) -> list[Row]:
    """Every figure of one world, in order: its sweep, its learned prior, its searches (or the
    search at scale), `dfa run` end to end, and the costs of its base policy's use."""
    from dfa_viz.bench.costs import cost_rows

    bench = BENCHES.get(name, WorldBench())
    if bench.closed_loop is not None:
        from dfa_viz.bench.closed_loop import bench_closed_loop, closed_loop_rows

        r = bench_closed_loop(name, pairs=bench.closed_loop, repeats=args.repeats)
        return closed_loop_rows(name, r)
    rows: list[Row] = list(sweep_rows(name, repeats=args.repeats)) if name in SWEPT else []
    if name in PAPER_WORLDS:  # the learned search prior on planted size-2 tasks
        rows += prior_rows(bench_prior(name, n_eval=args.prior_tasks))
    if bench.at_scale:
        from dfa_viz.bench.tabletop import bench_rows, bench_tabletop

        figures = bench_tabletop(repeats=args.repeats)
        rows += [(f"{name}: {w}", v, t, ok) for w, v, t, ok in bench_rows(figures)]
    if bench.searches:
        rows += search_rows(name, bench, args.repeats)
    run_s = bench_run(name, policy=bench.policy)
    if bench.searches:
        what = f"{shown(name, bench)}: `dfa run` end to end, policy loaded"
        rows.append((what, f"{run_s:.1f} s", "< 30 s", run_s < 30))
    if bench.policy is None:  # the costs of finetuning and the experiment: own policies only
        rrd = Path("recordings") / "bench" / files.safe_name(f"{name}-object_ti-seed0.rrd")
        rows += cost_rows(name, run_s, rrd, repeats=args.repeats)
    return rows


def page_rows() -> list[Row]:
    """The web page's figures in Chromium, each against its target where it has one."""
    from dfa_viz.bench.page import bench_page

    rows: list[Row] = []
    for key, value in bench_page().items():
        shown = f"{value:.3g}" if isinstance(value, float) else str(value)
        limit = PAGE_TARGETS.get(key)
        ok = None if limit is None else float(value) <= limit
        rows.append((f"page: {key}", shown, "" if limit is None else f"<= {limit:g}", ok))
    return rows


def write_rows(rows: list[tuple[str, str, str, str]], out: Path) -> None:
    """Print the table and write it to `out` as Markdown."""
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


def run_bench(args: BenchArgs) -> list[tuple[str, str, str, str]]:
    """Measure, print a table, and write it as Markdown to `args.out`.

    Rows are (what, value, target, met). The page figures need Chromium and take a minute or
    two; they are measured when `args.page` is set.
    """
    measured = [row for name in args.worlds for row in world_rows(name, args)]
    if args.page:
        measured += page_rows()
    rows = [(w, v, t, "" if ok is None else ("yes" if ok else "NO")) for w, v, t, ok in measured]
    write_rows(rows, args.out)
    return rows
