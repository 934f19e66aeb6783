"""What one tab draws from: a consistent copy of the page's loop state."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dfa_viz.app.jobs import Job
from dfa_viz.loop import AdaptConfig
from dfa_viz.run_record import RunRecord
from sim.core import World


@dataclass(frozen=True)
class View:
    """A consistent copy of the state for one tab to draw from."""

    version: int
    world_name: str
    """The world the page shows (the session's, or the loaded task's)."""
    world: World | None
    """The loaded task's world (None before a task is loaded)."""
    record: RunRecord | None
    stage: str
    job: Job | None
    error: str
    losses: tuple[float, ...]
    demo_kind: str
    demo_hint: str
    demo_summary: str
    demo_given: bool
    """The user has demonstrated something (a click, a key)."""
    demo_ready: bool
    demo_problem: str
    """Why the demonstration given so far cannot be used ("" when it can)."""
    recording: Path | None
    session: Path
    adapt: AdaptConfig
    finetuned: bool = False
    """The task was finetuned with the marks it has now: finetuning again would repeat it."""
