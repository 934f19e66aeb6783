"""Planted size-k tasks for any benchmark world: a training task with k looks changed.

A planted task is a training layout with k distinct (slot, concept) looks of present objects
each set to another value of the concept space; it keeps the training task's reward. It is kept
only when it is what it claims: the base policy fails on it, the world's expert solves it, no
single edit explains the failure and some edit of k changes does (a complete search finds
size k). Undoing the planted changes is one such edit, but not always the only one.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from policy.model import Policy
from search.counterfactual import SearchConfig, SearchResult, counterfactual_search
from search.prior import LearnedPrior, fit, search_log
from sim.core import Benchmark, Change, Edit, Task, Trajectory

PLANT_STREAM = 23  # rng stream of the planting, apart from the world's own streams


@dataclass(frozen=True)
class Planted:
    """An accepted planted task and what accepting it took.

    changes: the k planted changes, from the training task's looks to the planted ones.
    demo: the expert's demonstration (succeeds under the task's reward).
    result: the complete search up to size k (first_only=False, no candidate limit); it
        tried every edit of sizes 1 .. k and found size k.
    """

    task: Task
    changes: tuple[Change, ...]
    demo: Trajectory
    result: SearchResult

    @property
    def undo(self) -> Edit:
        """The edit that takes every planted look back to the training task's."""
        return Edit.of(*(Change(c.slot, c.concept, c.new, c.old) for c in self.changes))


def plant(
    world: Benchmark,
    seed: int,
    k: int,
    *,
    concepts: Sequence[tuple[str, str]] | None = None,
) -> tuple[Task, tuple[Change, ...]] | None:
    """The training task of `seed` with k distinct looks of present objects changed, each to a
    value drawn uniformly from the others; None when the scene has fewer than k looks to change.
    Deterministic per (seed, k); nothing is checked here (see `accept`).

    concepts: the k looks to change, (slot, concept), the first the task's cause: a cause
        fixed in advance (the bench's); None when one is not a look of a present object.
        Default: k drawn at random, in the space's order.
    """
    base = world.train_task(seed)
    rng = np.random.default_rng([seed, k, PLANT_STREAM])
    looks = [
        (s.name, c)
        for s in world.space.slots
        if base.scene.obj(s.name).present
        for c in s.concepts
        if len(c.values) > 1
    ]
    if concepts is None:
        if len(looks) < k:
            return None
        chosen = [looks[i] for i in sorted(rng.choice(len(looks), size=k, replace=False))]
    else:
        assert len(set(concepts)) == len(concepts) == k, f"{k} distinct looks, not {concepts}"
        by_name = {(slot, c.name): (slot, c) for slot, c in looks}
        if any(name not in by_name for name in concepts):
            return None
        chosen = [by_name[name] for name in concepts]
    changes = []
    for slot, concept in chosen:
        old = base.scene.obj(slot).value(concept.name)
        others = [v for v in concept.values if v != old]
        changes.append(Change(slot, concept.name, old, others[rng.integers(len(others))]))
    scene = world.apply(base.scene, Edit.of(*changes))
    cause = (changes[0].slot, changes[0].concept)
    task = replace(base, scene=scene, shift="object_tr", seed=seed, cause=cause)
    return task, tuple(changes)


def accept(world: Benchmark, policy: Policy, seed: int, k: int) -> Planted | None:
    """`plant(world, seed, k)` when it is what it claims, else None: the policy fails, the
    expert succeeds, no single edit is valid and a complete search finds size k."""
    planted = plant(world, seed, k)
    if planted is None:
        return None
    task, changes = planted
    if world.success(task, world.rollout(task, policy.act).scenes):
        return None
    demo = world.demonstrate(task)
    if not demo.success:
        return None
    config = SearchConfig(max_size=k, first_only=False, max_candidates=None)
    result = counterfactual_search(world, policy, task.scene, demo, config=config, task=task)
    if result.size != k:
        return None
    return Planted(task, changes, demo, result)


def planted_tasks(
    world: Benchmark,
    policy: Policy,
    seeds: Iterable[int],
    k: int,
    n: int,
    *,
    on_seed: Callable[[int, bool], None] | None = None,
) -> Iterator[Planted]:
    """The first n accepted planted tasks of `seeds`, in seed order; `on_seed(seed, accepted)`
    after each seed tried."""
    found = 0
    for seed in seeds:
        if found >= n:
            return
        p = accept(world, policy, seed, k)
        if on_seed is not None:
            on_seed(seed, p is not None)
        if p is not None:
            found += 1
            yield p


def fit_on_planted(
    world: Benchmark,
    policy: Policy,
    *,
    n: int,
    k: int = 2,
    first_seed: int = 0,
    l2: float = 1.0,
    on_seed: Callable[[int, bool], None] | None = None,
) -> tuple[LearnedPrior, list[Planted]]:
    """A LearnedPrior fitted on the searches of the first n accepted planted size-k tasks from
    `first_seed` on; the training scenes of every seed tried give the value frequencies."""
    tried: list[int] = []

    def seen(seed: int, accepted: bool) -> None:
        tried.append(seed)
        if on_seed is not None:
            on_seed(seed, accepted)

    seeds = itertools.count(first_seed)
    found = list(planted_tasks(world, policy, seeds, k, n, on_seed=seen))
    logs = [search_log(world, policy, p.task.scene, p.demo, p.result) for p in found]
    scenes = [world.train_task(s).scene for s in tried]
    return fit(world, logs, scenes, l2=l2), found


__all__ = ["Planted", "accept", "fit_on_planted", "plant", "planted_tasks"]
