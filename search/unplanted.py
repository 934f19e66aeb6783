"""Failures the benchmark's generator did not plant, and their ground truth from exhaustive
interventions.

A planted test task is a training layout with one concept changed, so undoing that change is
nearly always a valid size-1 edit by construction. The tasks here are not built around an
answer:

compound   a training task with two atomic changes of the concept space at once, drawn at
           random (seeded) among the changes of two different objects: a look of a present
           object, or a presence (an object added with the look and place the scene keeps for
           it, or one removed); R' is the training task's.
moved      the same two changes made to the world's own position shift (the `other` test
           task: a layout no concept edit can express, e.g. nav2d's goal in the corner training
           never shows it); only for worlds that have that shift.
natural    a training task of the world as it is, on which the policy fails with no edit at
           all (an outside agent's own failures: nothing is planted).

A task is kept only where the policy fails it and the world's expert meets R' on it.

The ground truth does not come from the generator: every effective edit of size 1 and 2 is
rolled out (lockstep, search.sweep.rollouts) and judged by the task's R'; the edits of the
smallest size under which the policy succeeds are the truth (`GroundTruth`), possibly none
within size 2. The counterfactual search, which matches the demonstration instead of reading
R', is measured against it by dfa_viz.experiment.unplanted.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from policy.model import Policy
from search.enumerate import combinations
from search.sweep.rollouts import roll
from sim.core import Benchmark, Change, Edit, Task, UserError, effective, single_changes

KINDS = ("compound", "moved", "natural")
UNPLANTED_STREAM = 29  # rng stream of the drawing, apart from the planting's (23)
EVAL_FROM = 1_000_000
"""Candidate seeds start here (x (seed + 1)): disjoint from the seeds 0 .. the learned prior is
fitted on (search.planted)."""
BATCH = 64  # candidate tasks whose unedited rollouts are stepped together


@dataclass(frozen=True)
class Unplanted:
    """A failing task and how it was made.

    changes: the generator's changes from the layout it started from (empty for natural).
    """

    task: Task
    kind: str
    changes: tuple[Change, ...]

    @property
    def undo(self) -> Edit | None:
        """The edit taking every generated change back (None for natural failures)."""
        if not self.changes:
            return None
        return Edit.of(*(Change(c.slot, c.concept, c.new, c.old) for c in self.changes))


@dataclass(frozen=True)
class GroundTruth:
    """Every edit of size 1 .. max_size rolled out under R'.

    edits: the edits under which the policy succeeds, of the smallest size that has one
        (sorted by their text); empty when none of size <= max_size does.
    restoring: every edit (any size tried) under which the policy succeeds.
    tried: how many edits of each size were rolled out, size 1 first.
    """

    edits: tuple[Edit, ...]
    restoring: frozenset[Edit]
    tried: tuple[int, ...]
    max_size: int

    @property
    def size(self) -> int | None:
        return self.edits[0].size if self.edits else None

    @property
    def slots(self) -> frozenset[str]:
        """The objects the minimal edits change."""
        return frozenset(c.slot for e in self.edits for c in e.changes)


def check_kind(world: Benchmark, kind: str) -> None:
    """A one-line UserError for a kind the world cannot make."""
    if kind not in KINDS:
        raise UserError(f"unknown kind {kind!r}; accepted: {', '.join(KINDS)}")
    if kind != "natural" and not world.benchmark:
        raise UserError(f"{world.name} has no training tasks to change; use --kind natural")
    if kind == "moved" and "other" not in world.shifts:
        raise UserError(f"{world.name} has no position shift ('other') to start from")


def candidate_seed(seed: int, k: int) -> int:
    """The k-th candidate task seed of run `seed`."""
    return EVAL_FROM * (seed + 1) + k


def draw(world: Benchmark, kind: str, cand: int) -> tuple[Task, tuple[Change, ...]] | None:
    """The candidate task `cand` of `kind`, unchecked; None when its scene has fewer than two
    objects to change. Deterministic per (kind, cand)."""
    if kind == "natural":
        return world.train_task(cand), ()
    base = world.train_task(cand) if kind == "compound" else world.test_task("other", cand)
    rng = np.random.default_rng([cand, UNPLANTED_STREAM, KINDS.index(kind)])
    presence, values = single_changes(world.space, base.scene)
    by_slot: dict[str, list[Change]] = {}
    for c in presence + values:
        if effective(base.scene, Edit.of(c)):
            by_slot.setdefault(c.slot, []).append(c)
    slots = sorted(by_slot, key=[s.name for s in world.space.slots].index)
    if len(slots) < 2:
        return None
    picked = sorted(rng.choice(len(slots), size=2, replace=False))
    changes = tuple(by_slot[slots[i]][rng.integers(len(by_slot[slots[i]]))] for i in picked)
    scene = world.apply(base.scene, Edit.of(*changes))
    task = replace(base, scene=scene, shift="other", seed=cand, cause=None)
    return task, changes


def failing(
    world: Benchmark,
    policy: Policy,
    kind: str,
    n: int,
    *,
    seed: int = 0,
    tries: int = 2000,
    on_batch: Callable[[int, int], None] | None = None,
) -> Iterator[Unplanted]:
    """The first n distinct candidates of run `seed` (in candidate order; a scene and R' seen
    before is skipped) that the policy fails and the expert solves; a UserError when `tries`
    candidates give fewer. `on_batch(tried, found)` after each batch."""
    check_kind(world, kind)
    found = 0
    seen: set = set()
    for start in range(0, tries, BATCH):
        ks = range(start, min(start + BATCH, tries))
        drawn = [d for k in ks if (d := draw(world, kind, candidate_seed(seed, k))) is not None]
        runs = roll(world, policy.act, [t for t, _ in drawn], [t.scene for t, _ in drawn])
        for (task, changes), run in zip(drawn, runs, strict=True):
            if run.success or (task.scene, task.reward) in seen:
                continue
            seen.add((task.scene, task.reward))
            if not world.demonstrate(task).success:
                continue
            yield Unplanted(task, kind, changes)
            found += 1
            if found == n:
                return
        if on_batch is not None:
            on_batch(ks.stop, found)
    raise UserError(
        f"{world.name}: only {found} failing {kind} tasks among {tries} candidates; ask for fewer"
    )


def ground_truth(world: Benchmark, policy: Policy, task: Task, *, max_size: int = 2) -> GroundTruth:
    """Every effective edit of sizes 1 .. max_size of the task's scene rolled out and judged by
    the task's R' (one lockstep batch per size)."""
    restoring: set[Edit] = set()
    tried: list[int] = []
    minimal: tuple[Edit, ...] = ()
    for size in range(1, max_size + 1):
        edits = list(combinations(world.space, task.scene, size))
        scenes = [world.apply(task.scene, e) for e in edits]
        runs = roll(world, policy.act, [task] * len(scenes), scenes)
        ok = [e for e, r in zip(edits, runs, strict=True) if r.success]
        restoring.update(ok)
        tried.append(len(edits))
        if ok and not minimal:
            minimal = tuple(sorted(ok, key=str))
    return GroundTruth(minimal, frozenset(restoring), tuple(tried), max_size)


def rank_in(order: Sequence[Edit], wanted: frozenset[Edit] | set[Edit]) -> int | None:
    """1-based position of the first edit of `order` in `wanted` (None: none is)."""
    return next((i + 1 for i, e in enumerate(order) if e in wanted), None)


__all__ = [
    "EVAL_FROM",
    "KINDS",
    "GroundTruth",
    "Unplanted",
    "candidate_seed",
    "check_kind",
    "draw",
    "failing",
    "ground_truth",
    "rank_in",
]
