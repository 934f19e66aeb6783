"""Evaluation: success on fresh tasks from the user's intended reward R', on the shift and overall.

The headline figure is success on fresh tasks that carry the test task's shift (every one has
the cause that made the base policy fail, in a training layout): did adaptation fix what the
user saw go wrong? Beside it, success on fresh tasks from all of R' (training looks included):
did it keep what the policy could already do?

Fresh means fresh: every fresh task stands on a training layout no finetuning trajectory starts
from, and those carrying a task-irrelevant shift show a value of its cause that no variant
shows, where the concept has enough values (policy.heldout). Among the candidates drawn, the
fresh tasks take distinct scenes first. `Freshness` reports beside every score how many
distinct scenes it was scored on and how many fresh tasks start from a scene (or a layout) a
finetuning trajectory starts from: 0 by construction.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from policy.heldout import Holdout, layout_of, plan
from policy.model import Policy
from sim.core import Scene, Task, Trajectory, UserError, World

N_EVAL = 10  # the paper's number of evaluation tasks
LAYOUTS = "train"  # fresh tasks put the objects as a random training layout does
POOL = 8  # candidates drawn per fresh task (and per held-out value) to find fresh ones in
FRESH_KEPT = 8  # test tasks whose fresh tasks a process keeps: a run scores two policies on
# them and reports their freshness, and a MiniGrid world plans each candidate to draw them
_FRESH: dict[tuple, tuple[World, list[Task], list[Task]]] = {}


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


def _pick(world: World, holdout: Holdout, pools: list[list[Task]], n: int) -> list[Task]:
    """n candidates on layouts no finetuning trajectory starts from, taken in turn from the
    pools, distinct scenes first (then the fresh ones again, in order, if too few)."""
    interleaved = [t for group in zip(*pools, strict=True) for t in group]
    fresh = [t for t in interleaved if holdout.fresh_layout(world, t.scene)]
    if not fresh:
        raise RuntimeError(
            f"no {world.name} fresh task off the finetuning layouts in {len(interleaved)} drawn"
        )
    distinct = list({t.scene: t for t in reversed(fresh)}.values())[::-1]
    return [distinct[i] if i < len(distinct) else fresh[i - len(distinct)] for i in range(n)]


def fresh(
    world: World, task: Task, *, n: int = N_EVAL, seed: int = 0, holdout: Holdout | None = None
) -> tuple[list, list]:
    """The fresh tasks a policy is scored on: (carrying the shift, from all of R'), on the
    layouts and, on the shift, the values `holdout` (default: heldout.plan) keeps from
    finetuning."""
    holdout = holdout or plan(world, task, seed)
    key = (id(world), task, n, seed, holdout)  # the world is kept beside: no other takes its id
    if key not in _FRESH:
        m = POOL * n
        shown = holdout.shown(task)
        shifted = [world.fresh_tasks(t, m, seed, layouts=LAYOUTS, shifted=True) for t in shown]
        overall = [world.fresh_tasks(task, m * len(shown), seed, layouts=LAYOUTS)]
        _FRESH[key] = (world, _pick(world, holdout, shifted, n), _pick(world, holdout, overall, n))
        while len(_FRESH) > FRESH_KEPT:
            del _FRESH[next(iter(_FRESH))]
    return list(_FRESH[key][1]), list(_FRESH[key][2])


@dataclass(frozen=True)
class Freshness:
    """How fresh one test task's fresh tasks are to the trajectories a policy was finetuned on."""

    distinct: int
    """Distinct starting scenes among the fresh tasks carrying the shift."""
    distinct_all: int
    """Distinct starting scenes among the fresh tasks from all of R'."""
    overlap: int
    """Fresh tasks (of both kinds) whose starting scene starts a finetuning trajectory."""
    layout_overlap: int
    """Fresh tasks whose layout a finetuning trajectory starts from."""
    held_layouts: int
    """Training layouts held out of finetuning for the evaluation."""
    held_values: tuple[str, ...]
    """Values of the cause no variant shows, which the fresh tasks carrying the shift show
    (() when the concept has too few: they then show the test task's value)."""
    n: int
    """Fresh tasks of each kind."""

    def to_json(self) -> dict:
        return {
            "distinct_scenes": self.distinct,
            "distinct_scenes_all": self.distinct_all,
            "overlap_with_finetuning": self.overlap,
            "layout_overlap_with_finetuning": self.layout_overlap,
            "held_out_layouts": self.held_layouts,
            "held_out_values": list(self.held_values),
        }

    def sentence(self) -> str:
        """In words, for reports: distinct scenes and the overlap with finetuning."""
        values = (
            f"the shift's {len(self.held_values)} held-out value(s)"
            if self.held_values
            else "the test task's value (too few to hold out)"
        )
        return (
            f"fresh tasks: {self.distinct}/{self.n} distinct scenes with the shift, "
            f"{self.distinct_all}/{self.n} overall; {self.overlap} start from a finetuning "
            f"scene, {self.layout_overlap} from a finetuning layout ({self.held_layouts} "
            f"layouts held out; {values})"
        )


def freshness(
    world: World,
    task: Task,
    starts: Sequence[Scene],
    *,
    n: int = N_EVAL,
    seed: int = 0,
    holdout: Holdout | None = None,
) -> Freshness:
    """How fresh the fresh tasks of `task` are to finetuning trajectories starting at `starts`
    (the demonstration's first scene and each variant's)."""
    holdout = holdout or plan(world, task, seed)
    shifted, overall = fresh(world, task, n=n, seed=seed, holdout=holdout)
    both = [*shifted, *overall]
    start_set = set(starts)
    layouts = {layout_of(world, s) for s in starts}
    return Freshness(
        len({t.scene for t in shifted}),
        len({t.scene for t in overall}),
        sum(t.scene in start_set for t in both),
        sum(layout_of(world, t.scene) in layouts for t in both),
        holdout.held_layouts,
        holdout.held_values,
        n,
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
