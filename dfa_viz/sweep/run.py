"""`dfa sweep`: the sweep (search.sweep) run on the backends with a progress bar, and its
outputs written: results.jsonl (each unit's result as it finishes: dfa_viz.sweep.journal),
sweep.csv, heatmap.png, sweep.rrd, and a table in the terminal.

A unit of work travels to a worker as itself (its tasks and, for pairs, its cells); the
policy travels by name (`SweepJob`): the base policy, or a spec policy.outside.load reads.
Units are fixed by the tasks alone and their results put in order by unit, so every backend
and any number of workers give the same result, and a sweep resumed from its results file the
result of one never stopped.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from dfa_viz.checked_policy import checked_policy
from dfa_viz.sweep.args import SweepArgs
from dfa_viz.sweep.figures import Heatmap
from dfa_viz.sweep.journal import RESULTS, Journal, kind
from search.sweep import (
    SweepProgress,
    SweepResult,
    Unit,
    UnitResult,
    run_unit,
    sweep,
    sweep_tasks,
)
from sim.core import UserError, World, files


@dataclass(frozen=True)
class SweepJob:
    """What every unit of one sweep shares: the world and the policy, by name."""

    world: str
    policy: str | None = None
    """A policy.outside spec; None: the world's base policy."""
    expert: bool | None = None
    """Check with the world's expert that R' can still be met (None: where it has one)."""


def run_unit_job(unit: Unit, job: SweepJob) -> UnitResult:
    """One unit on a worker (the backends' job function)."""
    from sim import get_world

    return run_unit(
        get_world(job.world), checked_policy(job.world, job.policy), unit, expert=job.expert
    )


def backend_runner(
    job: SweepJob,
    *,
    backend: str = "local",
    workers: int = 1,
    ray_address: str | None = None,
    on_unit: Callable[[Unit, UnitResult], None] | None = None,
) -> Callable[[Sequence[Unit]], list[UnitResult]]:
    """A search.sweep Runner on a backend (one worker: here, with one torch thread, as in a
    worker); on_unit(unit, result) as each unit finishes, in the process that runs the sweep."""
    from dfa_viz.backends import run_all

    def runner(units: Sequence[Unit]) -> list[UnitResult]:
        done: list[UnitResult] = []
        by_index = {u.index: u for u in units}

        def on_result(result: UnitResult) -> None:
            done.append(result)
            if on_unit is not None:
                on_unit(by_index[result.unit], result)

        run_all(
            run_unit_job,
            list(units),
            job,
            backend=backend,
            workers=workers,
            on_result=on_result,
            ray_address=ray_address,
            in_process=True,
        )
        return sorted(done, key=lambda r: r.unit)

    return runner


@dataclass(frozen=True)
class SweepOutput:
    result: SweepResult
    out: Path
    csv: Path
    heatmap: Path
    recording: Path
    wall_s: float
    """The sweep itself (rollouts on the backend), outputs apart."""


def out_folder(args: SweepArgs) -> Path:
    """--out, or recordings/sweep/<world>."""
    out = (
        args.out
        if args.out is not None
        else Path("recordings") / "sweep" / files.safe_name(args.world)
    )
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} is a file; give a folder for the sweep's files")
    return out


def check(args: SweepArgs, world: World) -> None:
    """Bad settings: one line each."""
    if args.tasks < 1:
        raise UserError(f"--tasks is how many tasks to sweep, at least 1, not {args.tasks}")
    if args.seed < 0:
        raise UserError(f"--seed must not be negative, got {args.seed}")
    bad = [s for s in args.sizes if s not in (1, 2)]
    if bad or not args.sizes:
        raise UserError(f"--sizes takes 1 and 2 (single edits, pairs), not {bad or '(none)'}")
    if args.worst < 0:
        raise UserError(f"--worst must not be negative, got {args.worst}")
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1, not {args.workers}")
    if args.address is not None and args.backend != "ray":
        raise UserError("--address names a Ray cluster: give it with --backend ray")


def header(args: SweepArgs, world: World) -> dict:
    """What makes a sweep's units what they are: its results file's first line."""
    return {
        "world": world.name,
        "policy": args.policy,
        "tasks": args.tasks,
        "seed": args.seed,
        "sizes": sorted(set(args.sizes)),
        "pair_cells": args.pair_cells if 2 in args.sizes else None,
    }


def run_sweep(args: SweepArgs) -> SweepOutput:
    """Sweep, appending each unit's result to OUT/results.jsonl as it finishes (with --resume:
    only the units not yet there), then write OUT/sweep.csv, OUT/heatmap.png and OUT/sweep.rrd,
    together: the table and the picture wait in temporary files until the recording is in
    place, so that a run cut short (a killed process, a full disk) leaves the last whole set as
    it was. A results file whose last line was cut short: one line on stderr."""
    from sim import get_world

    world = get_world(args.world)
    check(args, world)
    out = out_folder(args)
    policy = checked_policy(world.name, args.policy)  # a bad spec: one line, before any work
    tasks = sweep_tasks(world, args.tasks, args.seed)
    name = args.policy or "base policy"
    job = SweepJob(world.name, args.policy)
    if args.resume:
        journal = Journal.resume(out / RESULTS, header(args, world))
        if journal.note is not None:
            print(f"dfa: note: {journal.note}", file=sys.stderr)
    else:
        journal = Journal.start(out / RESULTS, header(args, world))

    from tqdm import tqdm

    bar = tqdm(total=0, desc="sweep", unit="unit", disable=not args.progress, leave=False)

    def on_unit(unit: Unit, result: UnitResult) -> None:
        journal.add(unit, result)
        bar.set_postfix_str(f"{kind(unit)}: {result.rollouts} rollouts", refresh=False)
        bar.update(1)

    def counted(units: Sequence[Unit]) -> list[UnitResult]:
        found = {u.index: journal.get(u) for u in units}
        kept = [r for r in found.values() if r is not None]
        bar.total += len(units)
        bar.update(len(kept))
        return sorted(kept + inner([u for u in units if found[u.index] is None]), key=_unit)

    inner = backend_runner(
        job,
        backend=args.backend,
        workers=args.workers,
        ray_address=args.address,
        on_unit=on_unit,
    )
    t0 = time.perf_counter()
    try:
        result = sweep(
            world,
            policy,
            tasks,
            sizes=tuple(sorted(set(args.sizes))),
            pair_cells=args.pair_cells,
            policy_name=name,
            runner=counted,
        )
    finally:
        bar.close()
    wall_s = time.perf_counter() - t0

    from dfa_viz.sweep.figures import heatmap, png_bytes
    from dfa_viz.sweep.recording import write_sweep_recording
    from dfa_viz.sweep.tables import csv_text

    picture = heatmap(world.space, result)
    csv, png, rrd = out / "sweep.csv", out / "heatmap.png", out / "sweep.rrd"
    with files.atomic_path(csv) as csv_tmp, files.atomic_path(png) as png_tmp:
        csv_tmp.write_text(csv_text(result))
        png_tmp.write_bytes(png_bytes(picture.image))
        write_sweep_recording(rrd, world, policy, result, heatmap=picture, worst=args.worst)
    return SweepOutput(result, out, csv, png, rrd, wall_s)


def _unit(result: UnitResult) -> int:
    return result.unit


PAGE_MAX_TASKS = 500


@dataclass(frozen=True)
class PageSweep:
    """A sweep as the page shows it: its world, result and heatmap."""

    world: str
    result: SweepResult
    heatmap: Heatmap


def page_sweep(
    world: World, policy, tasks: int, *, on_progress: SweepProgress | None = None
) -> PageSweep:
    """The Sweep tab's sweep: single edits over `tasks` training tasks, here."""
    if not 1 <= tasks <= PAGE_MAX_TASKS:
        raise UserError(f"sweep from 1 to {PAGE_MAX_TASKS} tasks, not {tasks}")
    from dfa_viz.sweep.figures import heatmap

    result = sweep(
        world,
        policy,
        sweep_tasks(world, tasks),
        policy_name=policy.source or "base policy",
        on_progress=on_progress,
    )
    return PageSweep(world.name, result, heatmap(world.space, result))
