"""Evaluation: success rate on fresh tasks drawn from the user's intended reward R'."""

from __future__ import annotations

from policy.model import Policy
from sim.core import Task, Trajectory, UserError, World

N_EVAL = 10  # the paper's number of evaluation tasks


def evaluate(
    world: World,
    policy: Policy,
    task: Task,
    *,
    n: int = N_EVAL,
    seed: int = 0,
    layouts: str = "task",
) -> float:
    """Fraction of n fresh tasks from task's R' that the policy solves (rolled out in one batch).

    layouts: where the fresh tasks put the objects (World.fresh_tasks).
    """
    tasks = world.fresh_tasks(task, n, seed, layouts=layouts)
    return sum(t.success for t in world.rollout_batch(tasks, policy)) / n


def failing_test_task(
    world: World, policy: Policy, shift: str, seed: int, *, tries: int = 200
) -> tuple[Task, Trajectory]:
    """The first task of kind `shift` in the seeded stream on which the policy fails.

    A test task is a shifted task the policy fails on: that is what there is to diagnose.
    Draws world.test_task(shift, seed * tries + k) for k = 0, 1, ... and returns the first
    failure with its rollout.
    """
    for k in range(tries):
        task = world.test_task(shift, seed * tries + k)
        rollout = world.rollout(task, policy)
        if not rollout.success:
            return task, rollout
    raise UserError(
        f"the base policy solved all {tries} {world.name} {shift} tasks drawn for seed {seed}: "
        "nothing to diagnose; try another seed or shift"
    )
