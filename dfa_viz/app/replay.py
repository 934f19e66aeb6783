"""Applying a session event to a run record: the loop's own step for each event, which returns
the next record.

Live, the job that made an event passes what it computed (`computed`: the new record for a
task, the demonstration, the diagnosis, the adaptation and evaluation), so nothing is done
twice. Replaying a session log rebuilds those values from what the event names: the task is
drawn again from its seed and the base policy rolled out, trajectory files are read back, a
search's counterfactual rollouts are rolled out again, the variants are made again from the
same seed, and a finetuning written without its scores is scored again from the checkpoint it
saved (`Rebuild`). Either way an event whose preconditions do not hold is a UserError.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from dfa_viz.app.events import (
    Demonstrated,
    Event,
    Finetuned,
    Judged,
    Marked,
    Searched,
    TaskLoaded,
    TieChosen,
)
from dfa_viz.loop import (
    adapted,
    augmentation,
    counterfactual_rollouts,
    demonstrated,
    diagnosed,
    judged,
    start,
)
from dfa_viz.run_record import Adaptation, Diagnosis, Evaluation, RunRecord
from policy import Policy, training_demos
from policy.evaluate import freshness, score
from sim import get_world
from sim.core import Label, Trajectory, UserError, World


@dataclass(frozen=True)
class Rebuild:
    """How applying an event gets what the event only names."""

    policy: Callable[[World], Policy]
    """The base policy of a world."""
    trajectory: Callable[[str], Trajectory]
    """A trajectory file of the session, by name."""
    checkpoint: Callable[[str, World], Policy]
    """A policy folder of the session, by name."""


def need(record: RunRecord | None, *stages: str) -> RunRecord:
    """The record, if the loop is at one of `stages`; else a UserError saying where it is."""
    if record is None:
        raise UserError("pick a task first")
    if record.stage not in stages:
        raise UserError(
            f"not now: the loop is at '{record.stage}', this needs {' or '.join(stages)}"
        )
    return record


def checked_label(world: World, label: Label) -> Label:
    """A mark's label with its acceptable values checked against the concept space."""
    values = world.space.values(label.slot, label.concept)
    bad = [v for v in label.acceptable if v not in values]
    if bad:
        raise UserError(f"{label.slot}.{label.concept} has no {bad}; accepted: {', '.join(values)}")
    if label.relevant:
        return dataclasses.replace(label, acceptable=())
    return label


def apply(
    record: RunRecord | None, event: Event, rebuild: Rebuild, computed: Any = None
) -> RunRecord:
    """The record after `event` (its preconditions checked: UserError if unmet), from what the
    live job `computed`, or rebuilt (see the module docstring)."""
    if isinstance(event, TaskLoaded):
        return computed if computed is not None else _task(event, rebuild)
    step = STEPS.get(type(event))
    if step is None:
        raise UserError(f"a {type(event).__name__} cannot be applied to a run")
    rec = need(record, *step[0])
    return step[1](rec, get_world(rec.world), event, rebuild, computed)


def _task(event: TaskLoaded, rebuild: Rebuild) -> RunRecord:
    world = get_world(event.world)
    if event.edit is not None:
        from search.sweep import Example, failure_task

        task = failure_task(world, Example(event.task_seed, event.edit, False, event.pos))
    else:
        task = world.test_task(event.shift, event.task_seed)
    return start(world, rebuild.policy(world), task, shift=event.shift, seed=event.seed)


def _judged(rec: RunRecord, world: World, event: Judged, rebuild: Rebuild, computed) -> RunRecord:
    return judged(rec, event.failed)


def _demonstrated(
    rec: RunRecord, world: World, event: Demonstrated, rebuild: Rebuild, computed
) -> RunRecord:
    demo = computed if computed is not None else rebuild.trajectory(event.file)
    if demo.scenes[0] != rec.task.scene or demo.horizon != len(rec.rollout.actions):
        raise UserError(f"{event.file} does not start from this task's scene")
    return demonstrated(rec, demo, event.source)


def _searched(rec: RunRecord, world: World, event: Searched, rebuild: Rebuild, computed):
    if computed is None:
        rollouts = counterfactual_rollouts(world, rebuild.policy(world), rec.task, event.result)
        computed = Diagnosis(event.result, tuple(rollouts))
    return diagnosed(rec, computed)


def _tie(rec: RunRecord, world: World, event: TieChosen, rebuild: Rebuild, computed):
    assert rec.diagnosis is not None  # the feedback stages come after the search
    n = min(len(rec.diagnosis.result.counterfactuals), len(rec.diagnosis.counterfactuals))
    if not 0 <= event.index < n:
        raise UserError(f"tie {event.index} does not exist; there are {n}")
    labels = {(lab.slot, lab.concept): lab for lab in rec.feedback.labels}
    diagnosis = dataclasses.replace(rec.diagnosis, tie=event.index)
    return dataclasses.replace(rec, diagnosis=diagnosis).keeping_labels(labels)


def _marked(rec: RunRecord, world: World, event: Marked, rebuild: Rebuild, computed):
    return rec.with_label(checked_label(world, event.label))


def _finetuned(rec: RunRecord, world: World, event: Finetuned, rebuild: Rebuild, computed):
    if computed is None:
        computed = _adaptation(rec, world, event, rebuild)
    return adapted(rec, *computed)


def _adaptation(
    rec: RunRecord, world: World, event: Finetuned, rebuild: Rebuild
) -> tuple[Adaptation, Evaluation | None]:
    """What the finetuning computed, from what its event saved: the variants made again (the
    same seed, the same set), the rollout read back, the scores (or scored again, for sessions
    written before scores were kept) and how fresh the scored tasks were to the finetuning."""
    assert rec.demo is not None  # the feedback stages come after the demonstration
    augmented: tuple[Trajectory, ...] = ()
    if event.config is not None:
        sourced = world.benchmark and event.config.finetuning.sources == "all"
        known = training_demos(world) if sourced else ()
        augmented = tuple(
            augmentation(
                world,
                rec.task,
                rec.demo,
                event.feedback,
                config=event.config,
                known=known,
                seed=rec.seed,
            )
        )
    budget = event.config.budget if event.config else event.n_augmented + 1
    rollout = rebuild.trajectory(event.rollout_file)
    adaptation = Adaptation(event.feedback, augmented, budget, event.losses, rollout)
    before, after = event.before, event.after
    if (before is None or after is None) and world.benchmark:
        tuned = rebuild.checkpoint(event.policy_dir, world)
        before = score(world, rebuild.policy(world), rec.task, seed=rec.seed)
        after = score(world, tuned, rec.task, seed=rec.seed)
    if before is None or after is None:
        return adaptation, None
    fresh = None  # how fresh the scored tasks were to the variants, where they are made again
    if event.config is not None:
        starts = [t.scenes[0] for t in (rec.demo, *augmented)]
        n = event.config.finetuning.n_eval
        fresh = freshness(world, rec.task, starts, n=n, seed=rec.seed)
    return adaptation, Evaluation(before, after, fresh)


FEEDBACK = ("feedback", "adapted")
STEPS: dict[type, tuple[tuple[str, ...], Callable[..., RunRecord]]] = {
    Judged: (("judge",), _judged),
    Demonstrated: (("demonstrate",), _demonstrated),
    Searched: (("diagnose",), _searched),
    TieChosen: (FEEDBACK, _tie),
    Marked: (FEEDBACK, _marked),
    Finetuned: (FEEDBACK, _finetuned),
}
"""Each event after the task: the stages it applies at and its step."""
