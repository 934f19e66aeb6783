"""One record of a run of the DFA loop (dfa_viz.loop): what each step found, kept as values.
Each step of the loop returns a new copy of a RunRecord; `dfa run --json` prints
`RunRecord.to_json()`, the recorder writes a run's .rrd from it and the page's session
persists it as events."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from policy import Policy
from policy.evaluate import Freshness, Score
from search import SearchResult
from search.stats import PairedChange, mcnemar_exact
from sim.core import Edit, Feedback, Label, Task, Trajectory


@dataclass(frozen=True)
class Diagnosis:
    """The counterfactual search's answer and the policy's rollouts from its minimal edits."""

    result: SearchResult
    counterfactuals: tuple[Trajectory, ...]
    """The policy from each minimal edit's scene (the first MAX_TIES), in the result's order."""
    tie: int = 0
    """The minimal edit the user looks at (and labels)."""

    @property
    def edit(self) -> Edit | None:
        if not self.result.found:
            return None
        return self.result.counterfactuals[self.tie].edit

    @property
    def counterfactual(self) -> Trajectory | None:
        if self.edit is None or self.tie >= len(self.counterfactuals):
            return None
        return self.counterfactuals[self.tie]

    def chosen(self) -> SearchResult:
        """The result with the chosen tie ranked first (what the user looked at)."""
        cands = self.result.counterfactuals
        if not cands or self.tie == 0:
            return self.result
        order = (cands[self.tie], *cands[: self.tie], *cands[self.tie + 1 :])
        return dataclasses.replace(self.result, counterfactuals=order)


@dataclass(frozen=True)
class Adaptation:
    """What adapting produced."""

    feedback: Feedback
    augmented: tuple[Trajectory, ...]
    """The distinct variants finetuned on beside the demonstration."""
    budget: int
    losses: tuple[float, ...]
    rollout: Trajectory
    """The finetuned policy on the test task."""
    policy: Policy | None = None
    """The finetuned policy (None when read back from a session)."""


@dataclass(frozen=True)
class Evaluation:
    """Both policies on the same fresh tasks, and how fresh those are to the finetuning."""

    before: Score
    after: Score
    fresh: Freshness | None = None
    """Distinct scenes and overlap with the finetuning trajectories (None when read back from
    a session that did not record it)."""

    def change(self, overall: bool = False) -> PairedChange:
        """The fresh tasks the finetuned policy newly solves and newly fails, and the exact
        one-sided McNemar p of a rise that large by chance: on the shift, or (overall) over
        all the user wants. Both policies face the same tasks, so the test pairs them; its
        units are the distinct scenes, which come first among the fresh tasks (a repeated
        scene is rolled out the same way again, no new evidence)."""
        before, after = (
            (self.before.overall, self.after.overall)
            if overall
            else (self.before.shifted, self.after.shifted)
        )
        if self.fresh is not None:
            units = self.fresh.distinct_all if overall else self.fresh.distinct
            before, after = before[:units], after[:units]
        return mcnemar_exact(before, after)


@dataclass(frozen=True)
class RunRecord:
    """One run of the loop on one test task, as far as it got."""

    world: str
    shift: str
    seed: int
    """The seed the run was asked for (the test task's own seed is task.seed)."""
    task: Task
    rollout: Trajectory
    """The base policy on the test task."""
    failed: bool | None = None
    """The user's judgement of that rollout (None: not judged yet)."""
    demo: Trajectory | None = None
    demo_source: str = ""
    diagnosis: Diagnosis | None = None
    feedback: Feedback = field(default_factory=Feedback)
    """The labels given so far (all of them once adapted)."""
    adaptation: Adaptation | None = None
    evaluation: Evaluation | None = None
    recording: str | None = None
    dataset: str | None = None
    """The LeRobotDataset the run was also written as (`dfa run --lerobot`)."""

    @property
    def stage(self) -> str:
        """judge, solved, demonstrate, diagnose, feedback or adapted."""
        if self.failed is None:
            return "judge"
        if not self.failed:
            return "solved"
        if self.demo is None:
            return "demonstrate"
        if self.diagnosis is None:
            return "diagnose"
        return "feedback" if self.adaptation is None else "adapted"

    @property
    def edit(self) -> Edit | None:
        return None if self.diagnosis is None else self.diagnosis.edit

    def label(self, slot: str, concept: str) -> Label | None:
        return next(
            (lab for lab in self.feedback.labels if (lab.slot, lab.concept) == (slot, concept)),
            None,
        )

    def unmarked(self) -> list[str]:
        """The edited concepts not labelled yet, as slot.concept."""
        edit = self.edit
        changes = edit.ordered if edit is not None else ()
        return [f"{c.slot}.{c.concept}" for c in changes if self.label(c.slot, c.concept) is None]

    def with_label(self, label: Label) -> RunRecord:
        """The record with `label` given (replacing an earlier one for its concept); labels
        stay in the order of the edit's changes, and only the edit's concepts are kept."""
        labels = {(lab.slot, lab.concept): lab for lab in self.feedback.labels}
        labels[(label.slot, label.concept)] = label
        return self.keeping_labels(labels)

    def keeping_labels(self, labels: dict[tuple[str, str], Label]) -> RunRecord:
        """The record with those of `labels` that the chosen edit changes, in its order."""
        edit = self.edit
        order = [(c.slot, c.concept) for c in edit.ordered] if edit is not None else []
        kept = tuple(labels[k] for k in order if k in labels)
        return dataclasses.replace(self, feedback=Feedback(kept))

    def to_json(self) -> dict[str, Any]:
        """The run as `dfa run --json` prints it (strict JSON: no NaN)."""
        d = self.diagnosis
        ad, ev = self.adaptation, self.evaluation
        return {
            "world": self.world,
            "shift": self.shift,
            "seed": self.seed,
            "task_seed": self.task.seed,
            "instruction": self.task.reward.instruction,
            "failed": self.failed,
            "counterfactual": [c.edit.to_list() for c in d.chosen().counterfactuals] if d else [],
            "candidates_tried": len(d.result.tried) if d else 0,
            "search_complete": d.result.complete if d else None,
            "search_epsilon": d.result.epsilon if d else None,
            "feedback": self.feedback.to_list(),
            "budget": ad.budget if ad else None,
            "augmented": len(ad.augmented) if ad else 0,
            "final_loss": ad.losses[-1] if ad and ad.losses else None,
            "success_before": ev.before.on_shift if ev else None,
            "success_after": ev.after.on_shift if ev else None,
            "success_all_before": ev.before.on_all if ev else None,
            "success_all_after": ev.after.on_all if ev else None,
            "change": {
                "on_shift": dataclasses.asdict(ev.change()),
                "all": dataclasses.asdict(ev.change(overall=True)),
            }
            if ev
            else None,
            "fresh": ev.fresh.to_json() if ev and ev.fresh else None,
            "recording": self.recording,
            "dataset": self.dataset,
        }
