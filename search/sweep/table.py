"""A sweep's outcomes kept trial by trial, so that other ways of searching the same edit space
can be replayed on it: a search asks for one trial at a time (one rollout: an edit on a
distinct task, at one place) and reads its outcome from the table instead of rolling it out.
Rollouts are deterministic here, so the answer is the one a rollout would give.

A *failure mode* is the sweep's own: a single edit whose failure rate beats the control arm
with its interval (Newcombe's paired 95% interval of the difference above 0, over every trial
of the edit). A search *confirms* a mode once the trials it has asked for already show it
by the same test; a trial's task's unedited rollout (the control) is paid for, one rollout,
the first time a search touches that task.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from search.stats import newcombe_paired
from search.sweep.cells import CellKey, cell_keys
from search.sweep.result import SweepResult
from search.sweep.units import Plan, UnitResult
from sim.core import World


@dataclass(frozen=True)
class Trial:
    """One rollout a search can ask for: an edit (arm) on a distinct task at a place."""

    arm: int
    task: int
    place: int
    adds: bool
    """The edit adds the object (absent from the task's scene)."""


@dataclass(frozen=True)
class OutcomeTable:
    """Every trial of a sweep's single edits, in the sweep's own order (task by task, each
    task's cells in the concept space's order, each cell's places in order), and its outcome.

    arms: the cells (slot, concept, value) with at least one trial.
    failed, counted: per trial, the policy failed; R' could still be met (the expert's check).
    control: per distinct task, the policy fails it unedited.
    modes: the arms whose difference from the control is above 0 with its interval.
    """

    world: str
    arms: tuple[CellKey, ...]
    trials: tuple[Trial, ...]
    failed: np.ndarray  # (N,) bool
    counted: np.ndarray  # (N,) bool
    control: np.ndarray  # (T,) bool
    modes: frozenset[int]

    @property
    def tasks(self) -> int:
        return len(self.control)

    @property
    def rollouts(self) -> int:
        """The whole table: every trial and every task's unedited rollout."""
        return len(self.trials) + self.tasks

    def hit(self, i: int) -> bool:
        """Trial i fails where its task unedited does not: a failure the edit is blamed for."""
        t = self.trials[i].task
        return bool(self.counted[i] and self.failed[i] and not self.control[t])

    def counts(self, trials: Sequence[int]) -> tuple[int, int, int, int]:
        """The paired 2x2 table (both fail, edited only, control only, neither) of the counted
        trials among `trials`."""
        c = [0, 0, 0, 0]
        for i in trials:
            if self.counted[i]:
                c[(not self.failed[i]) * 2 + (not self.control[self.trials[i].task])] += 1
        return c[0], c[1], c[2], c[3]

    def confirms(self, trials: Sequence[int]) -> bool:
        """The trials (of one arm) show the edit fails more often than the control arm."""
        counts = self.counts(trials)
        return sum(counts) > 0 and newcombe_paired(*counts)[0] > 0


def outcome_table(world: World, p: Plan, results: Sequence[UnitResult]) -> OutcomeTable:
    """The single edits' trials of a sweep's units (in the order `sweep` runs them)."""
    keys = cell_keys(world.space)
    order = {k: i for i, k in enumerate(keys)}
    outcomes = sorted(
        (o for r in results for o in r.outcomes if not isinstance(o.key[0], tuple)),
        key=lambda o: (o.task, order[o.key], o.place),  # type: ignore[index]
    )
    used = sorted({order[o.key] for o in outcomes})  # type: ignore[index]
    arm = {keys[k]: a for a, k in enumerate(used)}
    control = np.zeros(len(p.distinct), bool)
    for r in results:
        for ref in r.references:
            control[ref.task] = ref.failed
    trials = tuple(
        Trial(
            arm[o.key],  # type: ignore[index]
            o.task,
            o.place,
            not p.distinct[o.task].scene.obj(o.key[0]).present,  # type: ignore[arg-type]
        )
        for o in outcomes
    )
    failed = np.array([o.failed for o in outcomes], bool)
    counted = np.array([o.solvable is not False for o in outcomes], bool)
    table = OutcomeTable(
        world.name, tuple(keys[k] for k in used), trials, failed, counted, control, frozenset()
    )
    by_arm = arm_trials(table)
    modes = frozenset(a for a, ts in enumerate(by_arm) if table.confirms(ts))
    return OutcomeTable(table.world, table.arms, trials, failed, counted, control, modes)


def arm_trials(table: OutcomeTable) -> list[list[int]]:
    """Per arm, its trials' indices in table order."""
    out: list[list[int]] = [[] for _ in table.arms]
    for i, t in enumerate(table.trials):
        out[t.arm].append(i)
    return out


def agrees(table: OutcomeTable, result: SweepResult) -> bool:
    """The table's modes are the sweep's: its single edits with difference_low > 0."""
    theirs = {c.key for c in result.cells if c.n and c.difference_ci[0] > 0}
    return theirs == {table.arms[a] for a in table.modes}


@dataclass(frozen=True)
class Trace:
    """One search's run over a table: after each rollout it spent, the modes it had
    confirmed, and the arms it confirmed that are not modes (false alarms on few trials)."""

    found: np.ndarray  # (R,) int: modes confirmed after rollout r + 1
    false_alarms: int

    def rollouts_to(self, k: int) -> int | None:
        """Rollouts spent when the k-th mode was confirmed (None: never; 0 for k <= 0)."""
        if k <= 0:
            return 0
        at = np.flatnonzero(self.found >= k)
        return int(at[0]) + 1 if len(at) else None

    def found_by(self, budget: int) -> int:
        """Modes confirmed within `budget` rollouts."""
        if budget <= 0 or not len(self.found):
            return 0
        return int(self.found[min(budget, len(self.found)) - 1])


def trace(table: OutcomeTable, order: Sequence[int]) -> Trace:
    """Replay `order` (trial indices, each at most once) on the table, paying a task's
    control rollout the first time one of its trials is asked for."""
    seen_task = np.zeros(table.tasks, bool)
    asked: list[list[int]] = [[] for _ in table.arms]
    confirmed: set[int] = set()
    found: list[int] = []
    modes = 0
    for i in order:
        t = table.trials[i]
        if not seen_task[t.task]:
            seen_task[t.task] = True
            found.append(modes)
        asked[t.arm].append(i)
        if t.arm not in confirmed and table.confirms(asked[t.arm]):
            confirmed.add(t.arm)
            modes += t.arm in table.modes
        found.append(modes)
    return Trace(np.array(found, int), len(confirmed - table.modes))


__all__ = ["OutcomeTable", "Trace", "Trial", "agrees", "arm_trials", "outcome_table", "trace"]
