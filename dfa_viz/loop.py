"""The DFA loop (the paper's Algorithm 1): diagnose, take feedback, adapt."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from dfa_viz.users import User
from policy import Policy, augment, evaluate, finetune
from policy.evaluate import N_EVAL
from policy.train import FINETUNE, TrainConfig
from search import Candidate, SearchConfig, SearchResult, counterfactual_search
from sim.core import EMPTY, Feedback, Task, Trajectory, World, require_success


class LoopObserver(Protocol):
    """What the recorder and the page subscribe to; every method is optional to act on."""

    def on_rollout(self, name: str, traj: Trajectory) -> None: ...
    def on_candidate(self, index: int, cand: Candidate) -> None: ...
    def on_search(self, result: SearchResult, counterfactual: Trajectory | None) -> None: ...
    def on_feedback(self, feedback: Feedback) -> None: ...
    def on_augmented(self, trajectories: list[Trajectory]) -> None: ...
    def on_loss(self, step: int, loss: float) -> None: ...
    def on_evaluation(self, before: float, after: float) -> None: ...


@dataclass
class LoopReport:
    """Everything one pass of the loop produced."""

    world: str
    seed: int
    task: Task
    failed: bool
    rollout: Trajectory
    demo: Trajectory | None = None
    search: SearchResult | None = None
    counterfactual: Trajectory | None = None
    feedback: Feedback = field(default_factory=Feedback)
    n_augmented: int = 0
    losses: list[float] = field(default_factory=list)
    success_before: float | None = None
    success_after: float | None = None
    finetuned: Policy | None = None
    recording: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "world": self.world,
            "shift": self.task.shift,
            "seed": self.seed,
            "task_seed": self.task.seed,
            "instruction": self.task.reward.instruction,
            "failed": self.failed,
            "counterfactual": [c.edit.to_list() for c in self.search.counterfactuals]
            if self.search
            else [],
            "candidates_tried": len(self.search.tried) if self.search else 0,
            "feedback": self.feedback.to_list(),
            "augmented": self.n_augmented,
            "final_loss": self.losses[-1] if self.losses else None,
            "success_before": self.success_before,
            "success_after": self.success_after,
            "recording": self.recording,
        }


def run_loop(
    world: World,
    policy: Policy,
    task: Task,
    user: User,
    *,
    search_config: SearchConfig = SearchConfig(),
    train_config: TrainConfig = FINETUNE,
    n_eval: int = N_EVAL,
    seed: int = 0,
    observer: LoopObserver | None = None,
    on_progress: Callable[[int, int, int], None] | None = None,
) -> LoopReport:
    """One pass of Algorithm 1 on `task` with `user` answering."""
    rollout = world.rollout(task, policy)
    if observer:
        observer.on_rollout("failed", rollout)
    report = LoopReport(world.name, seed, task, user.judge(task, rollout), rollout)
    if not report.failed:
        return report

    # Diagnosis: the user's demonstration, then the smallest edit that explains the failure.
    demo = user.demonstrate(task)
    require_success(task, demo)
    report.demo = demo
    if observer:
        observer.on_rollout("demonstration", demo)
    counter = iter(range(10**9))
    result = counterfactual_search(
        world,
        policy,
        task.scene,
        demo,
        config=search_config,
        on_candidate=(lambda c: observer.on_candidate(next(counter), c)) if observer else None,
        on_progress=on_progress,
    )
    report.search = result
    if result.best is not None:
        edited = world.apply(task.scene, result.best.edit)
        report.counterfactual = world.rollout(task, policy, scene=edited)
    if observer:
        observer.on_search(result, report.counterfactual)

    # Feedback: each edited concept marked TI or TR; augment over the TI ones.
    finetune_set = [demo]
    report.feedback = user.label(task, result.best.edit if result.best is not None else EMPTY)
    if result.best is not None:
        augmented = augment(world, task, demo, report.feedback, seed=seed)
        report.n_augmented = len(augmented)
        finetune_set += augmented
        if observer:
            observer.on_feedback(report.feedback)
            observer.on_augmented(augmented)

    # Adaptation: finetune a copy, evaluate both on fresh tasks from R'.
    tuned, losses = finetune(
        world,
        policy,
        finetune_set,
        config=TrainConfig(train_config.steps, train_config.batch_size, train_config.lr, seed),
        on_loss=observer.on_loss if observer else None,
    )
    report.finetuned, report.losses = tuned, losses
    report.success_before = evaluate(world, policy, task, n=n_eval, seed=seed)
    report.success_after = evaluate(world, tuned, task, n=n_eval, seed=seed)
    if observer:
        observer.on_evaluation(report.success_before, report.success_after)
        observer.on_rollout("finetuned", world.rollout(task, tuned))
    return report
