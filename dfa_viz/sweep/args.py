"""The options of `dfa sweep` (SweepArgs). Light to import: nothing here loads torch, MuJoCo,
rerun or viser.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal


@dataclass(frozen=True)
class SweepArgs:
    """Find what breaks a policy before a user meets it: every single concept edit on many tasks.

    On TASKS tasks of the training distribution (seeds SEED, SEED + 1, ...), every value of
    every concept of every slot, and every object added or removed, is rolled out in lockstep
    beside the unedited task; an added object also where the world says it is in the way (a
    DoorKey lava on the path). Each edit's failure rate at what the task asks for (counted
    where the expert can still do it) and its mean action deviation from the unedited
    rollout, with 95% intervals; edits and concepts ranked, most damaging first. With
    --sizes 1 2, pairs of the edits that move the policy most, and those that fail more often
    than both alone.

    Writes OUT/sweep.csv, OUT/heatmap.png (failure rate, slot.concept x value) and
    OUT/sweep.rrd (the heatmap, a bar chart per concept, the worst edited rollouts beside the
    unedited ones), and prints the ranking. The same tasks give the same files on every
    backend. `dfa serve` has the same sweep in its Sweep tab, a click loading a failure.
    """

    world: str = "nav2d"
    """A registered world (`dfa worlds` lists them)."""
    policy: str | None = None
    """The policy to sweep instead of the base policy (a checkpoint folder, onnx:, torch:,
    sb3:, as for `dfa run`)."""
    tasks: int = 100
    """How many tasks (the same scene is rolled out once however often it comes)."""
    seed: int = 0
    """The first task's seed."""
    sizes: tuple[int, ...] = (1,)
    """Edit sizes: 1 (single edits), 1 2 (and pairs)."""
    workers: int = 1
    """Units of work side by side (1: in this process; more: a process pool or Ray CPUs)."""
    backend: Literal["local", "ray"] = "local"
    """local (processes on this machine) or ray (pip install 'dfa[ray]')."""
    out: Path | None = None
    """The folder for the files; when left out, recordings/sweep/<world>."""
    worst: int = 4
    """Edited rollouts shown in the recording, beside their unedited ones."""
    pair_cells: int = 32
    """With pairs: the edits paired, those that move the policy most."""
    ray_address: str | None = None
    """An existing Ray cluster ("auto", "ray://host:10001"); default: start one here."""
    progress: bool = True
    """Show a progress bar."""
