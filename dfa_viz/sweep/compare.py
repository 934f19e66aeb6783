"""`dfa experiment search`: the sweep's failure modes found by other ways of searching its edit
space (search.sweep.strategies), each replayed on the sweep's own outcomes (search.sweep.table):
one sweep per world, kept trial by trial, then every search asks that table one trial (one
rollout) at a time. Writes OUT/<world>.json, then OUT/table.md and OUT/modes.png from every
world's JSON in OUT."""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

from dfa_viz.checked_policy import checked_policy
from dfa_viz.records import figure_text, load_records
from dfa_viz.sweep.args import SearchArgs
from dfa_viz.sweep.run import SweepJob, backend_runner
from search.sweep import plan, summarise, sweep_tasks
from search.sweep.compare import MILESTONES, compare
from search.sweep.strategies import STOCHASTIC, STRATEGIES, prior_order, prior_scores
from search.sweep.table import agrees, outcome_table
from sim.core import UserError, files

NAMES = {
    "exhaustive": "exhaustive sweep (its order)",
    "uniform": "uniform random trials",
    "surrogate": "random-forest surrogate (FATE-style)",
    "reinforce": "REINFORCE over edits (RoboMD-style)",
    "prior": "learned prior's order",
}


def check(args: SearchArgs) -> None:
    if args.tasks < 1:
        raise UserError(f"--tasks is how many tasks to sweep, at least 1, not {args.tasks}")
    if args.seeds < 1:
        raise UserError(f"--seeds must be at least 1, not {args.seeds}")
    if not 0 < args.budget_share <= 1:
        raise UserError(
            f"--budget-share is a share of the rollouts, in (0, 1], not {args.budget_share}"
        )
    if args.prior_tasks < 0:
        raise UserError(f"--prior-tasks must not be negative, got {args.prior_tasks}")
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1, not {args.workers}")


def command(args: SearchArgs) -> str:
    """The command line that makes this world's results."""
    parts = ["dfa experiment search", f"--world {args.world}"]
    if args.policy:
        parts.append(f"--policy {args.policy}")
    parts += [f"--tasks {args.tasks}", f"--seeds {args.seeds}", f"--prior-tasks {args.prior_tasks}"]
    if args.budget_share != 0.25:
        parts.append(f"--budget-share {args.budget_share}")
    return " ".join(parts)


def run_search_comparison(args: SearchArgs) -> dict:
    """The sweep once, the prior fitted (where the world has an expert), every search on the
    table; the world's JSON written and the folder's table and figure rebuilt."""
    from sim import get_world

    check(args)
    world = get_world(args.world)
    policy = checked_policy(world.name, args.policy)
    say = print if args.progress else (lambda *a, **k: None)
    tasks = sweep_tasks(world, args.tasks)
    p = plan(tasks)
    from tqdm import tqdm

    units = p.units(world)
    t0 = time.perf_counter()
    with tqdm(total=len(units), desc="sweep", unit="unit", disable=not args.progress) as bar:
        runner = backend_runner(
            SweepJob(world.name, args.policy),
            workers=args.workers,
            on_unit=lambda unit, result: bar.update(1),
        )
        results = runner(units)
    sweep_s = time.perf_counter() - t0
    result = summarise(world, p, results, policy=args.policy or "base policy")
    table = outcome_table(world, p, results)
    assert agrees(table, result), "the table's failure modes differ from the sweep's"
    say(
        f"{world.name}: sweep of {len(table.trials)} trials on {table.tasks} distinct tasks "
        f"in {sweep_s:.1f} s; {len(table.modes)} failure modes"
    )
    strategies = dict(STRATEGIES)
    prior_s = math.nan
    if args.prior_tasks and world.benchmark:
        from search.planted import fit_on_planted

        t0 = time.perf_counter()
        prior, _ = fit_on_planted(world, policy, n=args.prior_tasks)  # type: ignore[arg-type]
        prior_s = time.perf_counter() - t0
        scenes = [t.scene for t in p.distinct]
        strategies["prior"] = prior_order(prior_scores(prior, world, scenes, table))
        say(
            f"{world.name}: learned prior fitted on {args.prior_tasks} planted tasks "
            f"in {prior_s:.1f} s"
        )
    t0 = time.perf_counter()
    runs = compare(
        table, strategies, seeds=args.seeds, stochastic=STOCHASTIC, budget_share=args.budget_share
    )
    compare_s = time.perf_counter() - t0
    record = {
        "world": world.name,
        "policy": args.policy or "base policy",
        "command": command(args),
        "tasks": args.tasks,
        "distinct": table.tasks,
        "edits": len(table.arms),
        "trials": len(table.trials),
        "rollouts": table.rollouts,
        "modes": sorted(f"{s}.{c}={v}" for s, c, v in (table.arms[a] for a in table.modes)),
        "budget_share": args.budget_share,
        "sweep_s": round(sweep_s, 1),
        "prior_s": None if math.isnan(prior_s) else round(prior_s, 1),
        "compare_s": round(compare_s, 1),
        "runs": [{**asdict(r), "curve": [round(v, 2) for v in r.curve]} for r in runs],
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    files.write_text(out / f"{files.safe_name(world.name)}.json", json.dumps(record) + "\n")
    write_summary(out)
    return record


def _fig(f: dict, digits: int = 0) -> str:
    return figure_text(f, digits)


def table_md(records: list[dict]) -> str:
    lines = [
        "# How fast each search finds the sweep's failure modes",
        "",
        "A failure mode is a single edit whose failure rate beats the control arm (the same "
        "tasks unedited) with its interval: Newcombe's paired 95% interval of the difference "
        "above 0 over every trial of the edit, the sweep's own test. A search *confirms* a mode "
        "once the trials it has asked for pass the same test. Each world's sweep was run once "
        "and kept trial by trial (an edit on a distinct task, at a place: one rollout; the "
        "worlds and policies roll out deterministically), and every search asked that table "
        "instead of rolling out again: a query is one rollout, and a task's unedited rollout "
        "(the control) costs one more the first time a search touches the task. Budget: the "
        "whole table (every search can ask every trial). Modes per 1,000 rollouts: those "
        "confirmed within the first quarter of the table's rollouts (or the share given). "
        "Stochastic searches: mean over seeds (95% t interval); the exhaustive sweep and the "
        "prior's order are one fixed order each. False alarms: edits a search's trials "
        "confirmed that the whole table does not (few trials, chance failures).",
        "",
        "| world | search | seeds | modes per 1,000 rollouts | rollouts to 50% | to 90% "
        "| to all | false alarms |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        head = (
            f"{r['world']} ({len(r['modes'])} modes, {r['edits']} edits, {r['distinct']} "
            f"distinct tasks, {r['rollouts']:,} rollouts)"
        )
        for run in r["runs"]:
            to = [_fig(f) for f in run["to"]]
            lines.append(
                f"| {head} | {NAMES.get(run['name'], run['name'])} | {run['seeds']} | "
                f"{_fig(run['per_1000'])} (first {run['budget']:,}) | {' | '.join(to)} | "
                f"{_fig(run['false_alarms'], 1)} |"
            )
            head = ""
    lines += [
        "",
        "## Commands",
        "",
        "Each writes its world's JSON and rebuilds this table and modes.png from every JSON in "
        "the folder. Times are wall times of one process (the sweep's units on --workers).",
        "",
    ]
    for r in records:
        prior = f", prior fitted in {r['prior_s']} s" if r.get("prior_s") is not None else ""
        lines.append(
            f"- `{r['command']}` (sweep {r['sweep_s']} s{prior}, searches {r['compare_s']} s)"
        )
    lines += ["", "## Failure modes", ""]
    for r in records:
        modes = r["modes"]
        listed = ", ".join(modes) if len(modes) <= 40 else f"{len(modes)} edits ({r['world']}.json)"
        lines.append(f"- {r['world']}: {listed or 'none'}")
    return "\n".join(lines) + "\n"


def write_summary(out: Path) -> None:
    records = load_records(out)
    files.write_text(out / "table.md", table_md(records))
    from dfa_viz.sweep.figures import png_bytes

    files.write_bytes(out / "modes.png", png_bytes(modes_figure(records)))


def modes_figure(records: list[dict]):
    """uint8 (H, W, 3): per world, the mean modes confirmed against rollouts, a line per search."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * max(1, len(records)), 3.6), dpi=110)
    FigureCanvasAgg(fig)
    for k, r in enumerate(records):
        ax = fig.add_subplot(1, max(1, len(records)), k + 1)
        for run in r["runs"]:
            y = np.array(run["curve"])
            ax.plot(np.arange(1, len(y) + 1), y, label=NAMES.get(run["name"], run["name"]))
        ax.axhline(len(r["modes"]), color="grey", lw=0.8, ls="--")
        ax.set_title(f"{r['world']} ({len(r['modes'])} modes)", fontsize=9, loc="left")
        ax.set_xlabel("rollouts", fontsize=8)
        ax.set_ylabel("failure modes confirmed", fontsize=8)
        ax.tick_params(labelsize=7)
        if k == 0:
            ax.legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()  # type: ignore[attr-defined]


__all__ = ["MILESTONES", "check", "command", "run_search_comparison", "table_md", "write_summary"]
