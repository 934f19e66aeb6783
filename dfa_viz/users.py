"""Who answers the loop's questions: the `User` protocol and a simulated user that reads R'."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from policy.variants import acceptable_if_irrelevant
from sim.core import Edit, Feedback, Label, Task, Trajectory, UserError, World


class User(Protocol):
    """The person in the loop (or a stand-in): judges, demonstrates, labels."""

    source: str
    """Where this user's demonstrations come from ("expert", "file", "clicks", "keys")."""

    def judge(self, task: Task, rollout: Trajectory) -> bool:
        """True when the rollout failed what the user wanted."""
        ...

    def demonstrate(self, task: Task) -> Trajectory:
        """One demonstration of the task from its initial scene."""
        ...

    def label(self, task: Task, edit: Edit) -> Feedback:
        """Mark each edited concept TI or TR, with the acceptable instantiations for TI (the
        edit is empty when the search found no counterfactual)."""
        ...


@dataclass
class SimulatedUser:
    """Answers from the task's R': the scripted expert demonstrates; labels come from R'.

    accuracy: probability that each label is right; otherwise the label is flipped (a TI
        concept called TR, or a TR one called TI with every instantiation accepted).
    overrides: (slot, concept) -> True (TR) / False (TI), answers fixed by hand.
    demo: a demonstration the user brought (e.g. loaded from .npz) instead of the expert's.
    on_asked: told "demonstrate" or "label" each time the loop asks (what `dfa run` shows as
        its progress).
    """

    world: World
    accuracy: float = 1.0
    seed: int = 0
    overrides: dict[tuple[str, str], bool] = field(default_factory=dict)
    demo: Trajectory | None = None
    on_asked: Callable[[str], None] | None = None

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng([self.seed, 7])

    @property
    def source(self) -> str:
        return "expert" if self.demo is None else "file"

    def judge(self, task: Task, rollout: Trajectory) -> bool:
        return not rollout.success

    def demonstrate(self, task: Task) -> Trajectory:
        if self.on_asked is not None:
            self.on_asked("demonstrate")
        return self.demo if self.demo is not None else self.world.demonstrate(task)

    def label(self, task: Task, edit: Edit) -> Feedback:
        if self.on_asked is not None:
            self.on_asked("label")
        changed = {(ch.slot, ch.concept) for ch in edit.changes}
        stray = [f"{s}.{c}" for s, c in self.overrides if (s, c) not in changed]
        if stray:
            touched = ", ".join(f"{s}.{c}" for s, c in sorted(changed)) or "nothing"
            raise UserError(
                f"--label {', '.join(stray)}: the counterfactual edit changes {touched}; "
                "a label answers for a concept the edit changes"
            )
        labels = []
        for ch in edit.ordered:
            relevant = task.reward.is_relevant(ch.slot, ch.concept)
            if (ch.slot, ch.concept) in self.overrides:
                relevant = self.overrides[(ch.slot, ch.concept)]
            elif self._rng.random() >= self.accuracy:
                relevant = not relevant
            labels.append(
                Label(
                    ch.slot,
                    ch.concept,
                    relevant,
                    self._acceptable(task, ch.slot, ch.concept, relevant),
                )
            )
        return Feedback(tuple(labels))

    def _acceptable(self, task: Task, slot: str, concept: str, relevant: bool) -> tuple[str, ...]:
        return () if relevant else acceptable_if_irrelevant(self.world, task.reward, slot, concept)
