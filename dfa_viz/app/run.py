"""What the page's loop state holds: the task being worked on (Run), a running job, and the
consistent copy (View) each tab draws from."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from dfa_viz.app.work import Adaptation
from search import SearchResult
from sim.core import Edit, Label, Task, Trajectory, UserError, World


@dataclass
class Run:
    """Everything about the task being worked on."""

    world: World
    shift: str
    seed: int
    task: Task
    rollout: Trajectory
    failed: bool | None = None
    demo: Trajectory | None = None
    demo_source: str = ""
    result: SearchResult | None = None
    counterfactuals: list[Trajectory] = field(default_factory=list)
    tie: int = 0
    marks: dict[tuple[str, str], Label] = field(default_factory=dict)
    adaptation: Adaptation | None = None

    @property
    def stage(self) -> str:
        if self.failed is None:
            return "judge"
        if not self.failed:
            return "solved"
        if self.demo is None:
            return "demonstrate"
        if self.result is None:
            return "diagnose"
        return "feedback" if self.adaptation is None else "adapted"

    @property
    def edit(self) -> Edit | None:
        """The selected minimal edit (a tie may be chosen), or None."""
        if self.result is None or not self.result.found:
            return None
        return self.result.counterfactuals[self.tie].edit

    @property
    def counterfactual(self) -> Trajectory | None:
        if self.edit is None or self.tie >= len(self.counterfactuals):
            return None
        return self.counterfactuals[self.tie]

    def unmarked(self) -> list[str]:
        edit = self.edit
        if edit is None:
            return []
        return [
            f"{c.slot}.{c.concept}" for c in edit.ordered if (c.slot, c.concept) not in self.marks
        ]


@dataclass(frozen=True)
class View:
    """A consistent copy of the state for one tab to draw from."""

    version: int
    world_name: str
    run: Run | None
    stage: str
    job: Job | None
    error: str
    losses: tuple[float, ...]
    demo_kind: str
    demo_hint: str
    demo_summary: str
    demo_ready: bool
    demo_problem: str
    """Why the demonstration given so far cannot be used ("" when it can)."""
    recording: Path | None
    session: Path


@dataclass(frozen=True)
class Job:
    name: str
    progress: float  # 0..1
    text: str


def need(run: Run | None, *stages: str) -> Run:
    """The run, if the loop is at one of `stages`; else a UserError saying where it is."""
    if run is None:
        raise UserError("pick a task first")
    if run.stage not in stages:
        raise UserError(f"not now: the loop is at '{run.stage}', this needs {' or '.join(stages)}")
    return run
