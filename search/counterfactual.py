"""The counterfactual search: the smallest concept edits under which the policy matches the demo."""

from __future__ import annotations

import itertools
import math
import typing
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from policy.model import Policy
from search.enumerate import combinations, count
from search.lockstep import Candidate, rollout_lockstep
from search.pauses import paused
from search.prior import LearnedPrior, unedited_candidate
from sim.core import Change, Scene, Task, Trajectory, UserError, World
from sim.core.world import Criterion

# (size, candidates done, candidates in this size) -> None
ProgressCallback = Callable[[int, int, int], None]
CandidateCallback = Callable[[Candidate], None]


@dataclass(frozen=True)
class SearchConfig:
    """How far and how the search looks."""

    max_size: int = 2
    """Largest edit size tried."""
    epsilon: float | None = None
    """Per-step L1 bound on action distance; the world's default when None (continuous only)."""
    wave: int = 1024
    """Candidates rolled out together in one lockstep wave."""
    first_only: bool = False
    """Stop at the first valid edit instead of returning every minimal one (large spaces)."""
    prior: bool = True
    """Order edits of size >= 2 by the first-step distances their single changes got."""
    joint_below: int = 512
    """When all sizes together have at most this many edits, roll them out in one pass (where
    the world's counterfactual "follows" the demonstration)."""
    max_candidates: int | None = None
    """Stop after this many candidates (the most promising first); None = no limit."""
    learned: LearnedPrior | None = None
    """A prior learned from past searches (search.prior), used instead of the first-step
    distances when set: edits of size >= 2 by the summed -log p of their changes, presence
    edits or not. It only orders: the same edits are tried and the same ones found."""

    @classmethod
    def for_world(cls, world: World, *, max_size: int = 2) -> SearchConfig:
        """Defaults a world asks for (e.g. `search_first_only` on large concept spaces)."""
        return cls(
            max_size=max_size,
            first_only=world.search_first_only,
            max_candidates=world.search_max_candidates,
        )


@dataclass(frozen=True)
class SearchResult:
    """What the search found.

    counterfactuals: every valid edit of the smallest size that has one, ranked presence
        changes first (an object that should not be there explains more than its looks), then
        by total action distance; empty when there is no counterfactual.
    tried: every candidate rolled out, in the order tried.
    size: the size of the counterfactuals, or None.
    """

    counterfactuals: tuple[Candidate, ...]
    tried: tuple[Candidate, ...]
    size: int | None
    max_size: int
    complete: bool = True
    """False when the search stopped at its candidate limit before trying every edit."""
    criterion: str = "follows"
    """What made an edit a counterfactual (World.counterfactual): "follows" the
    demonstration step by step, or "succeeds" at the task."""
    epsilon: float | None = None
    """The per-step L1 bound an edit's rollout kept under (continuous worlds that "follow"):
    the one asked for, or less where the failed rollout itself never left it (`bound`); None
    where no bound applies."""
    asked: float | None = None
    """The bound asked for (the world's ε, or SearchConfig.epsilon); None where none applies."""

    @property
    def found(self) -> bool:
        return bool(self.counterfactuals)

    def to_json(self) -> dict:
        return {
            "size": self.size,
            "max_size": self.max_size,
            "complete": self.complete,
            "criterion": self.criterion,
            "epsilon": self.epsilon,
            "asked": self.asked,
            "counterfactuals": [c.to_dict() for c in self.counterfactuals],
            "tried": [c.to_dict() for c in self.tried],
        }

    @classmethod
    def from_json(cls, d: dict) -> SearchResult:
        """Read back `to_json` (UserError if malformed); `complete` defaults to True and
        `criterion` to "follows", `epsilon` and `asked` to None."""
        criterion = d.get("criterion", "follows")
        if criterion not in typing.get_args(Criterion):
            raise UserError(f"malformed search result (criterion {criterion!r})")
        try:
            return cls(
                tuple(Candidate.from_dict(c) for c in d["counterfactuals"]),
                tuple(Candidate.from_dict(c) for c in d["tried"]),
                d["size"],
                d["max_size"],
                bool(d.get("complete", True)),
                criterion,
                _epsilon(d.get("epsilon")),
                _epsilon(d.get("asked")),
            )
        except (KeyError, TypeError) as e:
            raise UserError(f"malformed search result ({type(e).__name__}: {e})") from None

    @property
    def tightened(self) -> bool:
        """True where the bound was tightened below the one asked for (`bound`)."""
        return self.epsilon is not None and self.asked is not None and self.epsilon < self.asked

    @property
    def best(self) -> Candidate | None:
        return self.counterfactuals[0] if self.counterfactuals else None

    def summary(self) -> str:
        if not self.found and not self.complete:
            return (
                f"no counterfactual among the {len(self.tried)} most promising edits of up to "
                f"{self.max_size} concept changes (the search stops there): the cause is most "
                "likely outside the concept space"
            )
        if not self.found:
            goal = "do the task" if self.criterion == "succeeds" else "follow the demonstration"
            return (
                f"no counterfactual: no edit of up to {self.max_size} concept changes makes the "
                f"policy {goal}; the cause is outside the concept space"
            )
        edits = "; or ".join(str(c.edit) for c in self.counterfactuals)
        return f"counterfactual of size {self.size}: {edits}"


@paused
def counterfactual_search(
    world: World,
    policy: Policy,
    scene: Scene,
    demo: Trajectory,
    *,
    config: SearchConfig = SearchConfig(),
    on_candidate: CandidateCallback | None = None,
    on_progress: ProgressCallback | None = None,
    task: Task | None = None,
) -> SearchResult:
    """Search edits of size 1, 2, ... for those after which the policy matches `demo` (or,
    where the world's counterfactual "succeeds", does `task`: search.lockstep).

    scene: the test task's initial scene (the demonstration starts from it).
    task: whose R' judges a rollout that "succeeds" (default: `world.task_for(scene)`).
    Stops at the first size with a valid edit and returns all valid edits of that size.
    """
    asked = world.epsilon if config.epsilon is None else config.epsilon
    eps = bound(world, policy, scene, demo, asked, task)
    if config.learned is not None:
        config.learned.check_world(world)
    # One pass over every size saves steps where candidates drop early; where every rollout
    # runs to the end ("succeeds"), larger sizes would cost their whole rollouts for nothing.
    if not config.first_only and world.counterfactual == "follows":
        sizes = {k: count(world.space, scene, k) for k in range(1, config.max_size + 1)}
        if sum(sizes.values()) <= config.joint_below:
            return _joint_search(
                world, policy, scene, demo, task, sizes, (eps, asked), on_candidate, on_progress
            )
    used = _used(world, eps, asked)
    tried: list[Candidate] = []
    prior: dict[Change, float] = {}
    totals: dict[int, int] = {}  # edits of each size, counted as the size is reached
    for size in range(1, config.max_size + 1):
        if size == 2 and config.learned is not None:
            unedited = unedited_candidate(world, policy, scene, demo, epsilon=eps, task=task)
            singles = [c for c in tried if c.edit.size == 1]
            prior = config.learned.costs(world.space, singles, unedited)
        ordered = size > 1 and (config.prior or config.learned is not None)
        edits = combinations(
            world.space,
            scene,
            size,
            prior=prior if ordered else None,
            grouped=config.learned is None,
        )  # generated as they are tried
        totals[size] = total = count(world.space, scene, size)
        done, valid = 0, []
        if on_progress is not None:
            on_progress(size, 0, total)
        while True:
            room = config.wave
            if config.max_candidates is not None:
                room = min(room, config.max_candidates - len(tried))
            wave = list(itertools.islice(edits, max(room, 0)))
            if not wave:
                break
            results = rollout_lockstep(world, policy, scene, demo, wave, epsilon=eps, task=task)
            for cand in results:
                tried.append(cand)
                if size == 1:
                    prior[next(iter(cand.edit.changes))] = float(cand.distances[0])
                if cand.valid:
                    valid.append(cand)
                if on_candidate is not None:
                    on_candidate(cand)
            done += len(wave)
            if on_progress is not None:
                on_progress(size, done, total)
            if valid and config.first_only:
                break
        if valid:
            return SearchResult(
                _rank(valid), tuple(tried), size, config.max_size, True, world.counterfactual, *used
            )
    complete = len(tried) == sum(totals.values())
    return SearchResult(
        (), tuple(tried), None, config.max_size, complete, world.counterfactual, *used
    )


def _rank(valid: list[Candidate]) -> tuple[Candidate, ...]:
    return tuple(sorted(valid, key=lambda c: (not c.edit.is_presence, c.total, str(c.edit))))


def _joint_search(
    world: World,
    policy: Policy,
    scene: Scene,
    demo: Trajectory,
    task: Task | None,
    totals: dict[int, int],
    bounds: tuple[float, float],
    on_candidate: CandidateCallback | None,
    on_progress: ProgressCallback | None,
) -> SearchResult:
    """Small spaces: every size in one lockstep pass (one sequence of steps instead of one per
    size), then the same answer as size by size. Larger sizes than the answer's are discarded
    without being reported."""
    eps, asked = bounds  # the bound used, the bound asked for
    used = _used(world, eps, asked)
    edits = [e for k in totals for e in combinations(world.space, scene, k)]
    results = rollout_lockstep(world, policy, scene, demo, edits, epsilon=eps, task=task)
    tried: list[Candidate] = []
    for size, total in totals.items():
        batch = [c for c in results if c.edit.size == size]
        tried += batch
        if on_candidate is not None:
            for cand in batch:
                on_candidate(cand)
        if on_progress is not None:
            on_progress(size, total, total)
        valid = [c for c in batch if c.valid]
        if valid:
            return SearchResult(
                _rank(valid), tuple(tried), size, max(totals), True, world.counterfactual, *used
            )
    return SearchResult((), tuple(tried), None, max(totals), True, world.counterfactual, *used)


def bound(
    world: World, policy: Policy, scene: Scene, demo: Trajectory, eps: float, task: Task | None
) -> float:
    """The per-step bound a candidate's rollout must keep under: `eps`, or, where the unedited
    scene's rollout already keeps under it at every step (a failure that drifts off the
    demonstration by less than eps a step, yet misses), the largest distance that rollout
    reaches, so that an edit counts only where the policy follows the demonstration more
    closely than it did when it failed. Without this the unedited scene would pass the test
    every counterfactual is held to. Only continuous worlds that "follow" have a bound."""
    if world.discrete or world.counterfactual != "follows":
        return eps
    unedited = unedited_candidate(world, policy, scene, demo, epsilon=eps, task=task)
    if not unedited.valid:
        return eps
    return float(np.nanmax(unedited.distances))


def _used(world: World, eps: float, asked: float) -> tuple[float | None, float | None]:
    """(the bound used, the bound asked for), or (None, None) where no bound applies."""
    return (None, None) if world.discrete or world.counterfactual != "follows" else (eps, asked)


def _epsilon(value: object) -> float | None:
    if value is None:
        return None
    if not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
        raise UserError(f"malformed search result (epsilon {value!r})")
    return float(value)
