"""The explanation benchmark as a whole: which tasks it holds (`ExplainPlan`) and running every
task not yet in its results folder, then its table, plot and sorted CSVs (`run_explain`); one
task is dfa_viz.experiment.explain."""

from __future__ import annotations

from dataclasses import dataclass

from dfa_viz.experiment.args import EXPLAIN_SHIFTS, EXPLAIN_WORLDS
from dfa_viz.experiment.experiment import Summary, run_resumable
from dfa_viz.experiment.explain import (
    EXPLAINERS,
    ExplainSettings,
    TaskSpec,
    explain_task,
)
from dfa_viz.experiment.explain_figures import write_plot
from dfa_viz.experiment.explain_results import explain_folder, write_table
from sim import check_world_name, get_world
from sim.core import UserError


@dataclass(frozen=True)
class ExplainPlan:
    """Which tasks a benchmark consists of: M seeds of every world and shift."""

    worlds: tuple[str, ...] = EXPLAIN_WORLDS
    shifts: tuple[str, ...] = EXPLAIN_SHIFTS
    tasks: int = 50

    def check(self) -> ExplainPlan:
        """Raise a one-line UserError for a world, shift or count that cannot be measured."""
        if self.tasks < 1:
            raise UserError(f"--tasks is how many tasks per world and shift, not {self.tasks}")
        if not self.worlds or not self.shifts:
            raise UserError("at least one world and one shift are needed")
        for name in self.worlds:
            world = get_world(check_world_name(name))
            if not world.benchmark:
                raise UserError(f"{name} makes no test tasks: it has no planted causes to find")
            for shift in self.shifts:
                if shift not in world.shifts or shift == "other":
                    planted = [s for s in world.shifts if s != "other"]
                    raise UserError(
                        f"{name} has no planted cause for shift {shift!r}; accepted: "
                        + ", ".join(planted)
                    )
        return self

    def specs(self) -> list[TaskSpec]:
        return [
            TaskSpec(w, s, seed)
            for w in dict.fromkeys(self.worlds)
            for s in dict.fromkeys(self.shifts)
            for seed in range(self.tasks)
        ]


def run_explain(
    plan: ExplainPlan,
    *,
    out,
    settings: ExplainSettings = ExplainSettings(),
    backend: str = "local",
    workers: int = 2,
    ray_address: str | None = None,
    progress: bool = True,
) -> Summary:
    """Run every task not yet in `out`, then write the table, the plot and the sorted CSVs."""
    bad = [e for e in settings.explainers if e not in EXPLAINERS]
    if bad or not settings.explainers:
        raise UserError(
            f"unknown explainer {bad[0] if bad else '(none)'!r}; accepted: {', '.join(EXPLAINERS)}"
        )
    if settings.max_size < 1:
        raise UserError(f"--max-size must be at least 1, not {settings.max_size}")
    plan.check()
    folder = explain_folder(out, settings)
    specs = plan.specs()

    def describe(result: dict) -> str:
        first = result["rows"][0]
        hits = sum(int(r["hit1"]) for r in result["rows"])
        return f"{first['world']} {first['shift']} s={first['seed']}: {hits} top-1 hits"

    skipped, executed, wall_s = run_resumable(
        explain_task,
        specs,
        folder,
        settings,
        worlds=plan.worlds,
        describe=describe,
        lines=lambda r: (r["rows"], r["timings"]),
        unit="task",
        backend=backend,
        workers=workers,
        ray_address=ray_address,
        progress=progress,
    )
    rows = folder.finalise()
    reports: tuple = ()
    if rows:
        timings = folder.timings()
        reports = (write_table(folder.out, rows, timings, settings), write_plot(folder.out, rows))
    return Summary(folder.out, len(specs), skipped, executed, wall_s, reports)
