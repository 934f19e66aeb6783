"""The whole comparison: plan the runs, skip finished ones, run the rest, write the reports."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from dfa_viz.backends import BACKENDS, run_all
from dfa_viz.experiment.conditions import CONDITIONS, PAPER_WORLDS, SHIFT_KINDS
from dfa_viz.experiment.figures import write_plots, write_rrd
from dfa_viz.experiment.folder import ResultsFolder
from dfa_viz.experiment.results import results_folder, write_table
from dfa_viz.experiment.runner import RunSpec, Settings, run_one
from sim.core import UserError


@dataclass(frozen=True)
class Plan:
    """Which runs an experiment consists of (the product of all its lists)."""

    worlds: tuple[str, ...] = PAPER_WORLDS
    shifts: tuple[str, ...] = SHIFT_KINDS
    conditions: tuple[str, ...] = CONDITIONS
    budgets: tuple[int, ...] = (5, 10, 25, 50, 75, 100)
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)

    def __post_init__(self) -> None:
        for name, values, accepted in (
            ("world", self.worlds, PAPER_WORLDS),
            ("shift", self.shifts, SHIFT_KINDS),
            ("condition", self.conditions, CONDITIONS),
        ):
            if not values:
                raise UserError(f"at least one {name} is needed; accepted: {', '.join(accepted)}")
            bad = [v for v in values if v not in accepted]
            if bad:
                raise UserError(f"unknown {name} {bad[0]!r}; accepted: {', '.join(accepted)}")
        if not self.budgets or min(self.budgets) < 1:
            raise UserError(
                f"budgets are numbers of finetuning trajectories, at least 1: {self.budgets}"
            )
        if not self.seeds or min(self.seeds) < 0:
            raise UserError(f"seeds are non-negative integers: {self.seeds}")

    def specs(self) -> list[RunSpec]:
        """Every run, ordered so that the runs of one task (world, shift, seed) are adjacent."""
        return [
            RunSpec(w, s, c, b, seed)
            for w in self.worlds
            for s in self.shifts
            for seed in self.seeds
            for c in self.conditions
            for b in sorted(set(self.budgets))
        ]


@dataclass(frozen=True)
class Summary:
    out: Path
    planned: int
    skipped: int
    executed: int
    wall_s: float
    reports: tuple[Path, ...]


def _warm_base_policies(worlds: Sequence[str]) -> None:
    """Train (or load) each base policy once here, with one torch thread as the workers use,
    so that workers find them cached instead of racing to train them."""
    import torch

    from policy import base_policy
    from sim import get_world

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for w in worlds:
            base_policy(get_world(w))
    finally:
        torch.set_num_threads(threads)


def run_resumable(
    job,
    specs: Sequence,
    folder: ResultsFolder,
    settings,
    *,
    worlds: Sequence[str],
    describe,
    lines,
    unit: str,
    backend: str,
    workers: int,
    ray_address: str | None,
    progress: bool,
) -> tuple[int, int, float]:
    """Run `job(spec, settings)` for every spec whose key is not yet done in `folder` on a
    backend, each result's (rows, timings) = `lines(result)` appended to it, with a progress
    bar whose postfix is `describe(result)`: what the q2 experiment and the explanation
    benchmark share.
    Returns (skipped, executed, seconds)."""
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; accepted: {', '.join(BACKENDS)}")
    finished = folder.done()
    todo = [s for s in specs if s.key not in finished]
    t0 = time.perf_counter()
    executed = 0
    if todo:
        _warm_base_policies(worlds)
        from tqdm import tqdm

        bar = tqdm(
            total=len(specs),
            initial=len(specs) - len(todo),
            desc=f"{unit}s",
            unit=unit,
            disable=not progress,
            smoothing=0.1,
        )

        def on_result(result) -> None:
            folder.append(*lines(result))
            bar.set_postfix_str(describe(result), refresh=False)
            bar.update(1)

        try:
            executed = run_all(
                job,
                todo,
                settings,
                backend=backend,
                workers=workers,
                on_result=on_result,
                ray_address=ray_address,
            )
        finally:
            bar.close()
    return len(specs) - len(todo), executed, time.perf_counter() - t0


def run_experiment(
    plan: Plan,
    *,
    out: Path,
    settings: Settings = Settings(),
    backend: str = "local",
    workers: int = 2,
    ray_address: str | None = None,
    progress: bool = True,
) -> Summary:
    """Run every planned run not yet in `out`, then write the table, plots and recording."""
    folder = results_folder(out, settings)
    specs = plan.specs()
    skipped, executed, wall_s = run_resumable(
        run_one,
        specs,
        folder,
        settings,
        worlds=plan.worlds,
        describe=lambda r: (
            f"{r['world']} {r['shift']} {r['condition']} b={r['budget']} s={r['seed']}: "
            f"{r['success']}"
        ),
        lines=lambda r: ([r], [r]),
        unit="run",
        backend=backend,
        workers=workers,
        ray_address=ray_address,
        progress=progress,
    )
    rows = folder.finalise()
    reports: tuple[Path, ...] = ()
    if rows:
        reports = (
            write_table(folder.out, rows, settings),
            *write_plots(folder.out, rows),
            write_rrd(folder.out, rows),
        )
    return Summary(folder.out, len(specs), skipped, executed, wall_s, reports)
