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

    Appends each unit of work's result to OUT/results.jsonl as it finishes (one JSON line,
    fsynced); --resume runs only the units not yet there. Then writes OUT/sweep.csv,
    OUT/heatmap.png (failure rate, slot.concept x value) and OUT/sweep.rrd (the heatmap, a bar
    chart per concept, the worst edited rollouts beside the unedited ones), and prints the
    ranking. The same tasks give the same files on every backend, resumed or not. `dfa serve`
    has the same sweep in its Sweep tab, a click loading a failure.
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
    """local (processes on this machine) or ray (pip install 'dfa[ray]'): a Ray instance with
    WORKERS CPUs started here, bound to 127.0.0.1, or the cluster at --address."""
    address: str | None = None
    """With --backend ray: an existing Ray cluster to run on (host:port of its head, "auto",
    ray://host:10001); its CPUs, not --workers, say how many units run at once."""
    resume: bool = False
    """Go on from OUT/results.jsonl, as a stopped sweep with the same options left it,
    running only the units not yet in it (without it: start afresh, replacing that file)."""
    out: Path | None = None
    """The folder for the files; when left out, recordings/sweep/<world>."""
    worst: int = 4
    """Edited rollouts shown in the recording, beside their unedited ones."""
    pair_cells: int = 32
    """With pairs: the edits paired, those that move the policy most."""
    progress: bool = True
    """Show a progress bar."""


@dataclass(frozen=True)
class SearchArgs:
    """Measure how fast other ways of searching the sweep's edit space find its failure modes.

    The sweep of WORLD's single edits on TASKS training tasks is run once and kept trial by
    trial (an edit on a distinct task at a place: one rollout, deterministic); each search then
    asks that table for one trial at a time instead of rolling it out: the exhaustive sweep in
    its order, uniform random sampling, a random-forest surrogate refitted as outcomes come in
    (FATE's manner), a REINFORCE softmax policy over edits rewarded by failure (RoboMD's
    manner), and the learned prior's order. A failure mode is an edit whose failure rate beats
    the control arm with its interval (the sweep's own test); a search confirms one once the
    trials it asked for show it by that test. Per search: modes confirmed per 1,000 rollouts
    within BUDGET_SHARE of the table's rollouts, and rollouts to confirm 50% / 90% / all of
    them (the stochastic searches over SEEDS seeds, mean and 95% t interval).

    Writes OUT/<world>.json, then OUT/table.md and OUT/modes.png from every world's JSON in
    OUT (run it once per world into the same folder).
    """

    world: str = "nav2d"
    """A registered world (`dfa worlds` lists them)."""
    policy: str | None = None
    """The policy instead of the base policy (a checkpoint folder, onnx:, torch:, sb3:)."""
    tasks: int = 100
    """How many training tasks the sweep runs on (seeds 0, 1, ...)."""
    seeds: int = 10
    """Seeds of each stochastic search (uniform, surrogate, reinforce)."""
    budget_share: float = 0.25
    """The share of the table's rollouts the per-1,000 rate is read at."""
    prior_tasks: int = 20
    """Planted tasks the learned prior is fitted on (0: leave the prior out; only worlds with
    training tasks and an expert have one)."""
    workers: int = 1
    """Units of the sweep side by side (a process pool)."""
    out: Path = Path("docs/results/sweep")
    """The results folder."""
    progress: bool = True
    """Show progress."""
