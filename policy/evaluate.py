"""Evaluation: success on fresh tasks from the user's intended reward R', on the shift and overall.

The headline figure is success on fresh tasks that carry the test task's shift (every one has
the cause that made the base policy fail, in a training layout): did adaptation fix what the
user saw go wrong? Beside it, success on fresh tasks from all of R' (training looks included):
did it keep what the policy could already do?
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from policy.model import Policy
from sim.core import Task, Trajectory, UserError, World

N_EVAL = 10  # the paper's number of evaluation tasks
LAYOUTS = "train"  # fresh tasks put the objects as a random training layout does


@dataclass(frozen=True)
class Score:
    """One policy's success on the fresh tasks of one test task."""

    shifted: tuple[bool, ...]
    """Per fresh task that carries the shift: solved?"""
    overall: tuple[bool, ...]
    """Per fresh task from all of R': solved?"""

    @property
    def on_shift(self) -> float:
        """Success rate on the shift (the headline figure)."""
        return sum(self.shifted) / len(self.shifted)

    @property
    def on_all(self) -> float:
        """Success rate over all of R'."""
        return sum(self.overall) / len(self.overall)

    def to_json(self) -> dict:
        return {
            "shifted": [int(s) for s in self.shifted],
            "overall": [int(s) for s in self.overall],
        }

    @classmethod
    def from_json(cls, d: dict) -> Score:
        return cls(tuple(bool(v) for v in d["shifted"]), tuple(bool(v) for v in d["overall"]))


def fresh(world: World, task: Task, *, n: int = N_EVAL, seed: int = 0) -> tuple[list, list]:
    """The fresh tasks a policy is scored on: (carrying the shift, from all of R')."""
    return (
        world.fresh_tasks(task, n, seed, layouts=LAYOUTS, shifted=True),
        world.fresh_tasks(task, n, seed, layouts=LAYOUTS),
    )


def score(world: World, policy: Policy, task: Task, *, n: int = N_EVAL, seed: int = 0) -> Score:
    """The policy rolled out on the 2n fresh tasks of `task` (one batch), judged by R'."""
    shifted, overall = fresh(world, task, n=n, seed=seed)
    solved = [r.success for r in world.rollout_batch([*shifted, *overall], policy)]
    return Score(tuple(solved[:n]), tuple(solved[n:]))


STREAM = 200  # task seeds per run seed: seed s draws test tasks s * STREAM + k, k = 0, 1, ...
DRAWN = 50  # tasks drawn before saying there is nothing to diagnose


def failing_test_task(
    world: World,
    policy: Policy,
    shift: str,
    seed: int,
    *,
    tries: int = DRAWN,
    who: str = "the base policy",
    on_draw: Callable[[int], None] | None = None,
) -> tuple[Task, Trajectory]:
    """The first task of kind `shift` in the seeded stream on which the policy fails.

    A test task is a shifted task the policy fails on: that is what there is to diagnose.
    Draws world.test_task(shift, seed * STREAM + k) for k = 0, 1, ... up to `tries` tasks and
    returns the first failure with its rollout; after `tries` successes, a UserError that says
    so (`who`: the policy, as the message names it). `on_draw(k)` after each task drawn.
    """
    if not 1 <= tries <= STREAM:
        raise UserError(f"tasks to draw must be from 1 to {STREAM}, not {tries}")
    for k in range(tries):
        task = world.test_task(shift, seed * STREAM + k)
        rollout = world.rollout(task, policy)
        if on_draw is not None:
            on_draw(k)
        if not rollout.success:
            return task, rollout
    raise UserError(
        f"{who} solved all {tries} {world.name} {shift} tasks drawn for seed {seed}: "
        "nothing to diagnose; try another seed or shift"
    )
