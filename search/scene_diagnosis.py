"""A failure a scene-parameter search found (search.scene_search), diagnosed in concepts: the
counterfactual search (search.counterfactual) run on the failing scene against the world's
expert demonstration of it, and its minimal edits replayed: the edit reported is the best
ranked one under which the policy's own rollout succeeds at the task, or, where none does, the
best ranked one (restores False); none where no edit of up to `max_size` changes makes the
policy follow the demonstration (or do the task, World.counterfactual)."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

from policy.model import Policy
from search.counterfactual import SearchConfig, counterfactual_search
from sim.core import Benchmark, Task


@dataclass(frozen=True)
class Diagnosis:
    """What the counterfactual search made of one failing scene."""

    edit: str | None
    """The minimal concept edit (None: none within max_size)."""
    size: int | None
    restores: bool
    """The policy, rolled out on the failing scene with `edit` applied, succeeds at the task."""
    counterfactuals: int
    """Valid edits of the minimal size."""
    restoring: int
    """Of those, the ones whose rollout succeeds."""
    tried: int
    complete: bool
    """False where the search stopped at its candidate limit."""
    max_size: int
    seconds: float
    changes: list | None = None
    """The edit as Edit.to_list() (read back with Edit.from_list)."""

    def summary(self) -> str:
        if self.edit is None:
            limit = "" if self.complete else f" among the {self.tried} edits tried"
            return f"none within size {self.max_size}{limit}"
        return f"{self.edit} (size {self.size}{'' if self.restores else ', does not restore'})"

    def to_dict(self) -> dict:
        return {
            "edit": self.edit,
            "size": self.size,
            "restores": self.restores,
            "counterfactuals": self.counterfactuals,
            "restoring": self.restoring,
            "tried": self.tried,
            "complete": self.complete,
            "max_size": self.max_size,
            "seconds": round(self.seconds, 2),
            "summary": self.summary(),
            "changes": self.changes,
        }


def diagnose(
    world: Benchmark,
    policy: Policy,
    task: Task,
    *,
    max_size: int = 2,
    max_candidates: int | None = None,
) -> Diagnosis:
    """The counterfactual search on `task` (a failing scene) against its expert demonstration;
    every minimal edit found rolled out to see whether it restores success."""
    t0 = time.perf_counter()
    demo = world.demonstrate(task)
    config = SearchConfig.for_world(world, max_size=max_size)
    if max_candidates is not None:
        config = replace(config, max_candidates=max_candidates)
    result = counterfactual_search(world, policy, task.scene, demo, config=config, task=task)
    found = list(result.counterfactuals)
    ok: list[bool] = []
    if found:
        scenes = [world.apply(task.scene, c.edit) for c in found]
        runs = world.rollout_batch([task] * len(found), policy.act, scenes=scenes)
        ok = [r.success for r in runs]
    best = next((c for c, s in zip(found, ok, strict=True) if s), found[0] if found else None)
    return Diagnosis(
        edit=None if best is None else str(best.edit),
        size=result.size,
        restores=bool(best is not None and ok[found.index(best)]),
        counterfactuals=len(found),
        restoring=sum(ok),
        tried=len(result.tried),
        complete=result.complete,
        max_size=max_size,
        seconds=time.perf_counter() - t0,
        changes=None if best is None else best.edit.to_list(),
    )


__all__ = ["Diagnosis", "diagnose"]
