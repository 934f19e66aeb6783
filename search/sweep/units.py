"""Sweep units: the distinct tasks of a sweep cut into pieces of work, and one piece rolled
out in lockstep (World.rollout_batch), every cell of every task at once.

A single cell that adds an object is tried where the scene keeps the object (place 0) and at
every position the world gives as in the way of the task (`World.in_the_way`, places 1, 2,
...); pairs are tried at place 0 only."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from policy.model import Policy
from search.sweep.cells import CellKey, PairKey, added_slot, cell_keys, key_edit
from search.sweep.rollouts import Run, replay_success, roll
from sim.core import Edit, Scene, Task, Trajectory, World

UNIT_ROLLOUTS = 512  # rollouts per unit of work (whole tasks; at least one task)

Ways = tuple[tuple[str, tuple[tuple[float, ...], ...]], ...]  # (slot, in_the_way places)


@dataclass(frozen=True)
class Unit:
    """One piece of work: consecutive distinct tasks and the cells to roll out on each."""

    index: int
    first: int
    """Index of its first task among the plan's distinct tasks."""
    tasks: tuple[Task, ...]
    pairs: tuple[PairKey, ...] = ()
    """The pair cells to roll out; empty: every single cell."""
    ways: tuple[Ways, ...] = ()
    """Per task, the places `World.in_the_way` gives for each slot an edit adds (worked out
    once, when the plan is cut into units; empty: worked out where the unit runs)."""


@dataclass(frozen=True)
class Plan:
    """The tasks as given, the distinct ones among them (rolled out once each), and which
    distinct task each given task is."""

    tasks: tuple[Task, ...]
    distinct: tuple[Task, ...]
    of: tuple[int, ...]

    def units(self, world: World, pairs: Sequence[PairKey] = ()) -> tuple[Unit, ...]:
        """Consecutive distinct tasks, as many per unit as fill UNIT_ROLLOUTS rollouts (at
        least one; each cell at each of its places): fixed by the tasks and cells alone,
        never by who runs them."""
        keys: Sequence[CellKey | PairKey] = pairs or cell_keys(world.space)
        out: list[Unit] = []
        start, count = 0, 0
        found: list[Ways] = []
        for i, task in enumerate(self.distinct):
            ways: dict[str, list[tuple[float, ...]]] = {}
            edits = [e for e in (key_edit(task.scene, k) for k in keys) if e is not None]
            count += 1 + sum(len(places(world, task, e, ways, pairs=bool(pairs))) for e in edits)
            found.append(tuple((slot, tuple(map(tuple, at))) for slot, at in ways.items()))
            if count >= UNIT_ROLLOUTS or i == len(self.distinct) - 1:
                todo = self.distinct[start : i + 1]
                out.append(Unit(len(out), start, todo, tuple(pairs), tuple(found)))
                start, count, found = i + 1, 0, []
        return tuple(out)


def plan(tasks: Sequence[Task]) -> Plan:
    """Tasks with the same scene and R' are rolled out once (rollouts are deterministic)."""
    index: dict[tuple[Scene, object], int] = {}
    distinct: list[Task] = []
    of = []
    for t in tasks:
        k = (t.scene, t.reward)
        if k not in index:
            index[k] = len(distinct)
            distinct.append(t)
        of.append(index[k])
    return Plan(tuple(tasks), tuple(distinct), tuple(of))


@dataclass(frozen=True)
class Reference:
    """A distinct task's own rollouts: the policy's unedited one, and the expert's."""

    task: int
    failed: bool
    expert_failed: bool | None
    """None: the world has no expert."""


@dataclass(frozen=True)
class Outcome:
    """One cell on one distinct task, at one place."""

    task: int
    key: CellKey | PairKey
    failed: bool
    """The policy's rollout from the edited scene fails R'."""
    solvable: bool | None
    """The expert meets R' after the edit (checked only where the policy failed; True where
    it succeeded); None without an expert."""
    deviation: float
    """Mean per-step action distance to the unedited rollout, over the steps where neither
    had ended (nan: none)."""
    expert_deviation: float
    """The same against the expert's demonstration of the unedited task (nan: no expert)."""
    place: int = 0
    """0: the scene as it is; k > 0: the object the edit adds moved to `pos` first."""
    pos: tuple[float, ...] | None = None
    """Where the added object was put (None: where the scene keeps it)."""


@dataclass(frozen=True)
class UnitResult:
    unit: int
    references: tuple[Reference, ...]
    outcomes: tuple[Outcome, ...]
    rollouts: int
    """Policy rollouts run (distinct edited scenes plus the unedited ones)."""
    frames: int
    """Observations that went through the policy."""


def _brief(world: World, traj: Trajectory) -> Run:
    live = np.array([not world.done(s) for s in traj.scenes[:-1]], bool)  # (T,)
    return Run(bool(traj.success), traj.actions, live)


def deviation(world: World, a: Run, b: Run) -> float:
    """Mean per-step action distance of two rollouts over the steps where neither had ended:
    L1 for continuous actions, 1 for a different discrete action; nan when no step is left."""
    mask = a.live & b.live  # (T,)
    if not mask.any():
        return math.nan
    if world.discrete:
        return float((a.actions[mask] != b.actions[mask]).mean())
    return float(np.abs(a.actions[mask] - b.actions[mask]).sum(axis=1).mean())


def run_unit(world: World, policy: Policy, unit: Unit, *, expert: bool | None = None) -> UnitResult:
    """Roll out every cell of the unit (and each task unedited) in lockstep; with an expert
    (default: a Benchmark world's), check that R' can still be met wherever the policy failed.
    """
    expert = world.benchmark if expert is None else expert
    frames = [0]

    def act(obs: np.ndarray) -> np.ndarray:  # (B, H, W, 3) -> (B, A) | (B,)
        frames[0] += len(obs)
        return policy.act(obs)

    jobs: list[_Job] = []
    tasks: list[Task] = []
    scenes: list[Scene] = []
    base: list[int] = []
    for i, task in enumerate(unit.tasks):
        seen: dict[Scene, int] = {task.scene: len(scenes)}
        base.append(len(scenes))
        tasks.append(task)
        scenes.append(task.scene)
        keys: Sequence[CellKey | PairKey] = unit.pairs or cell_keys(world.space)
        ways: dict[str, list[tuple[float, ...]]] = (
            {slot: list(at) for slot, at in unit.ways[i]} if unit.ways else {}
        )
        for key in keys:
            edit = key_edit(task.scene, key)
            if edit is None:
                continue
            for place, pos in enumerate(places(world, task, edit, ways, pairs=bool(unit.pairs))):
                scene = world.apply(moved(task.scene, edit, pos), edit)
                if scene not in seen:
                    seen[scene] = len(scenes)
                    tasks.append(task)
                    scenes.append(scene)
                jobs.append(_Job(unit.first + i, key, seen[scene], place, pos))
    runs = roll(world, act, tasks, scenes)

    demos: list[Run | None] = [None] * len(unit.tasks)
    demo_actions: list[np.ndarray] = []
    if expert:
        for i, task in enumerate(unit.tasks):
            demo = world.demonstrate(task)  # type: ignore[attr-defined]
            demos[i] = _brief(world, demo)
            demo_actions.append(demo.actions)
    solvable = _solvable(world, unit, jobs, tasks, scenes, runs, demo_actions) if expert else {}

    refs = tuple(
        Reference(
            unit.first + i,
            not runs[base[i]].success,
            None if demos[i] is None else not demos[i].success,  # type: ignore[union-attr]
        )
        for i in range(len(unit.tasks))
    )
    outcomes = []
    for job in jobs:
        i = job.task - unit.first
        run, ref, demo = runs[job.rollout], runs[base[i]], demos[i]
        outcomes.append(
            Outcome(
                job.task,
                job.key,
                not run.success,
                None if not expert else (True if run.success else solvable[job.rollout]),
                deviation(world, run, ref),
                math.nan if demo is None else deviation(world, run, demo),
                job.place,
                job.pos,
            )
        )
    return UnitResult(unit.index, refs, tuple(outcomes), len(scenes), frames[0])


@dataclass(frozen=True)
class _Job:
    task: int
    key: CellKey | PairKey
    rollout: int
    place: int
    pos: tuple[float, ...] | None


def places(
    world: World,
    task: Task,
    edit: Edit,
    cache: dict[str, list[tuple[float, ...]]] | None = None,
    *,
    pairs: bool = False,
) -> list[tuple[float, ...] | None]:
    """Where a cell's edit of the task is tried: [None] (the scene as it is), then, for a
    single edit that adds an object, every position `World.in_the_way` gives for it."""
    slot = None if pairs else added_slot(edit)
    if slot is None:
        return [None]
    cache = {} if cache is None else cache
    if slot not in cache:
        cache[slot] = list(world.in_the_way(task, slot))
    return [None, *cache[slot]]


def moved(scene: Scene, edit: Edit, pos: tuple[float, ...] | None) -> Scene:
    """The scene with the object the edit adds at `pos` (unchanged for None)."""
    if pos is None:
        return scene
    slot = added_slot(edit)
    assert slot is not None, f"{edit} adds no object to put at {pos}"
    return scene.with_obj(replace(scene.obj(slot), pos=tuple(pos)))


def _solvable(world, unit, jobs, tasks, scenes, runs, demo_actions) -> dict[int, bool]:
    """For each rollout the policy failed: can the expert meet R' from that edited scene?
    First its unedited demonstration's actions replayed there (all at once), then, where
    that fails, its own closed-loop demonstration. An object added at a place the world gives
    as in the way leaves R' within reach (`World.in_the_way`): those are not checked."""
    placed = {j.rollout for j in jobs if j.place > 0}
    out: dict[int, bool] = dict.fromkeys(placed, True)
    failed = sorted({j.rollout for j in jobs if not runs[j.rollout].success} - placed)
    if not failed:
        return out
    owner = {j.rollout: j.task - unit.first for j in jobs}
    actions = np.stack([demo_actions[owner[r]] for r in failed])  # (F, T[, A])
    replayed = replay_success(
        world, [tasks[r] for r in failed], [scenes[r] for r in failed], actions
    )
    for r, ok in zip(failed, replayed, strict=True):
        out[r] = ok or bool(
            world.demonstrate(tasks[r].with_scene(scenes[r])).success  # type: ignore[attr-defined]
        )
    return out
