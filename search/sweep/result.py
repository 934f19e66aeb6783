"""The sweep's result: per cell and per concept, failure rates beside the control arm's (the
same tasks unedited) and their difference, deviations, all with 95% intervals over distinct
starting scenes, ranked by the difference; pairs that fail more often than both their cells.

A trial is one distinct starting scene: a task given twice (the same scene and R') is rolled
out once and counted once, since the worlds and policies roll out deterministically. Each
trial is paired with its task's unedited rollout (the control); the difference's interval is
Newcombe's for paired rates (search.stats.newcombe_paired)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from search.stats import newcombe_paired, t_interval, wilson
from search.sweep.cells import CellKey, PairKey, cell_keys, key_edit, label
from search.sweep.units import Outcome, Plan, UnitResult
from sim.core import PRESENCE, Edit, World
from sim.core.concepts import Slot


@dataclass(frozen=True)
class Example:
    """A task on which a cell's edit made the policy fail (R' still reachable): the task's
    seed and the edit, enough to load it as a task to diagnose (`failure_task`)."""

    seed: int
    edit: Edit
    base_failed: bool
    """The policy failed that task unedited too (only chosen when no other failure exists)."""
    pos: tuple[float, ...] | None = None
    """Where the object the edit adds was put (None: where the task's scene keeps it)."""


@dataclass(frozen=True)
class SweepCell:
    """One (slot, concept, value), or a pair of them, over the tasks it applies to."""

    key: CellKey | PairKey
    applies: int
    """Trials on which the edit changes something: one per distinct task, or, for an edit
    that adds an object, one per place it is tried at on each distinct task."""
    n: int
    """Of those, the trials counted: where R' can still be met after the edit."""
    failures: int
    failure_ci: tuple[float, float]
    control_failures: int
    """Of the counted trials, those whose task the policy fails unedited (the control arm)."""
    difference_ci: tuple[float, float]
    """95% interval of failure_rate - control_rate (paired: Newcombe)."""
    deviation: float
    deviation_ci: tuple[float, float]
    expert_deviation: float
    """Mean action distance to the expert's demonstration of the unedited task (nan: none)."""
    example: Example | None
    singles_rate: float = math.nan
    """Pairs: the larger failure rate of its two cells alone, on the same tasks."""

    @property
    def unsolvable(self) -> int:
        """Trials on which the edit leaves R' out of the expert's reach (not counted)."""
        return self.applies - self.n

    @property
    def failure_rate(self) -> float:
        return self.failures / self.n if self.n else math.nan

    @property
    def control_rate(self) -> float:
        """The control arm's failure rate: the same trials' tasks unedited."""
        return self.control_failures / self.n if self.n else math.nan

    @property
    def difference(self) -> float:
        """How much more often the policy fails with the edit than without, on the same tasks."""
        return self.failure_rate - self.control_rate

    @property
    def excess(self) -> float:
        """Pairs: how much more often the pair fails than either of its cells alone."""
        return self.failure_rate - self.singles_rate

    @property
    def label(self) -> str:
        return label(self.key)

    @property
    def is_pair(self) -> bool:
        return isinstance(self.key[0], tuple)

    @property
    def first(self) -> CellKey:
        """The cell itself, or a pair's first cell."""
        return self.key[0] if self.is_pair else self.key  # type: ignore[return-value]

    @property
    def slot(self) -> str:
        return self.first[0]

    @property
    def concept(self) -> str:
        return self.first[1]

    @property
    def value(self) -> str:
        return self.first[2]


@dataclass(frozen=True)
class ConceptDamage:
    """One slot.concept, all its values pooled over the trials of its cells. A look concept
    (colour, shape, ...) counts where its object is in the scene; a look given to an object
    that is absent comes with adding it, and counts toward that slot's presence."""

    slot: str
    concept: str
    n: int
    failures: int
    failure_ci: tuple[float, float]
    deviation: float
    worst: CellKey | None
    """Its most damaging value's cell."""
    control_failures: int = 0
    difference_ci: tuple[float, float] = (math.nan, math.nan)

    @property
    def failure_rate(self) -> float:
        return self.failures / self.n if self.n else math.nan

    @property
    def control_rate(self) -> float:
        return self.control_failures / self.n if self.n else math.nan

    @property
    def difference(self) -> float:
        return self.failure_rate - self.control_rate


@dataclass(frozen=True)
class SweepResult:
    """A whole sweep: every single cell ranked most damaging first (the difference from the
    control arm, then the failure rate, then deviation), the concepts ranked the same way, and
    with pairs the interactions: pairs that fail more often than both of their cells alone."""

    world: str
    policy: str
    seeds: tuple[int, ...]
    distinct: int
    """Distinct tasks among the seeds' (the same scene is rolled out once)."""
    base_failures: int
    """Distinct tasks the policy fails unedited."""
    expert: bool
    cells: tuple[SweepCell, ...]
    concepts: tuple[ConceptDamage, ...]
    pairs: tuple[SweepCell, ...] = ()
    """Every pair rolled out, ranked by excess."""
    rollouts: int = 0
    frames: int = 0
    sizes: tuple[int, ...] = (1,)

    @property
    def interactions(self) -> tuple[SweepCell, ...]:
        """The pairs that fail more often than both their cells alone, on the same tasks."""
        return tuple(p for p in self.pairs if p.n and p.excess > 0)

    @property
    def tasks(self) -> int:
        return len(self.seeds)

    def cell(self, slot: str, concept: str, value: str) -> SweepCell:
        for c in self.cells:
            if c.key == (slot, concept, value):
                return c
        raise KeyError((slot, concept, value))

    def concept_rank(self, slot: str, concept: str) -> int:
        """1 for the most damaging concept."""
        for i, c in enumerate(self.concepts):
            if (c.slot, c.concept) == (slot, concept):
                return i + 1
        raise KeyError((slot, concept))


def _rank_key(c: SweepCell | ConceptDamage) -> tuple:
    """Counted first; then the larger difference from the control, failure rate, deviation."""
    return (c.n == 0, -_or(c.difference, -2.0), -_or(c.failure_rate, -1.0), -_or(c.deviation, -1.0))


def _or(x: float, default: float) -> float:
    return default if x != x else x


def summarise(
    world: World,
    p: Plan,
    results: Sequence[UnitResult],
    *,
    policy: str,
    pairs: Sequence[UnitResult] = (),
    sizes: tuple[int, ...] = (1,),
) -> SweepResult:
    """The sweep's figures from its units' results (in any order)."""
    base = {r.task: r.failed for res in results for r in res.references}
    expert = any(r.expert_failed is not None for res in results for r in res.references)
    single = _index(results)
    cells = [_cell(p, key, single, base) for key in cell_keys(world.space)]
    cells = [c for c in cells if c.applies]
    concepts = [
        _concept(p, s.name, name, cells, single, base)
        for s in world.space.slots
        for name in _concept_names(s)
    ]
    pair_cells = []
    if pairs:
        both = _index(pairs)
        keys = dict.fromkeys(
            o.key for res in sorted(pairs, key=lambda r: r.unit) for o in res.outcomes
        )
        pair_cells = [_cell(p, k, both, base, single) for k in keys]
        pair_cells.sort(key=lambda c: (c.n == 0, -c.excess if c.n else 0.0, *_rank_key(c)))
    every = [*results, *pairs]
    return SweepResult(
        world.name,
        policy,
        tuple(t.seed for t in p.tasks),
        len(p.distinct),
        sum(base.values()),
        expert,
        tuple(sorted(cells, key=_rank_key)),
        tuple(sorted(concepts, key=_rank_key)),
        tuple(pair_cells),
        sum(r.rollouts for r in every),
        sum(r.frames for r in every),
        sizes,
    )


Index = dict[tuple[int, CellKey | PairKey], list[Outcome]]


def _index(results: Sequence[UnitResult]) -> Index:
    """(distinct task, key) -> its outcomes, place by place."""
    out: Index = {}
    for res in results:
        for o in res.outcomes:
            out.setdefault((o.task, o.key), []).append(o)
    for v in out.values():
        v.sort(key=lambda o: o.place)
    return out


def _concept_names(s: Slot) -> list[str]:
    return ([PRESENCE] if s.optional else []) + [c.name for c in s.concepts]


def _counted(o: Outcome | None) -> bool:
    return o is not None and o.solvable is not False


def _cell(
    p: Plan,
    key: CellKey | PairKey,
    outcomes: Index,
    base: dict[int, bool],
    single: Index | None = None,
) -> SweepCell:
    """One cell over the distinct tasks (a task given twice counts once), each place a trial,
    paired with the task unedited. A pair counts where it and both its cells count (at place
    0)."""
    applies = 0
    fails = [0, 0]
    table = _Paired()
    devs: list[float] = []
    edevs: list[float] = []
    example: Example | None = None
    fallback: Example | None = None
    for d, task in enumerate(p.distinct):
        for o in outcomes.get((d, key), ()):
            applies += 1
            if math.isfinite(o.deviation):
                devs.append(o.deviation)
            if math.isfinite(o.expert_deviation):
                edevs.append(o.expert_deviation)
            parts = () if single is None else tuple(_first(single, d, k) for k in key)
            if not (_counted(o) and all(_counted(x) for x in parts)):
                continue
            table.add(o.failed, base[d])
            for j, x in enumerate(parts):
                fails[j] += x.failed  # type: ignore[union-attr]
            if o.failed and example is None:
                edit = key_edit(task.scene, key)
                assert edit is not None
                ex = Example(task.seed, edit, base[d], o.pos)
                if not base[d]:
                    example = ex
                elif fallback is None:
                    fallback = ex
    mean, low, high = t_interval(devs)
    n = table.n
    return SweepCell(
        key,
        applies,
        n,
        table.failures,
        wilson(table.failures, n),
        table.control_failures,
        table.interval(),
        mean,
        (low, high),
        math.fsum(edevs) / len(edevs) if edevs else math.nan,
        example or fallback,
        max(fails) / n if single is not None and n else math.nan,
    )


class _Paired:
    """Trials tallied as a paired 2x2 table: (edited failed, control failed)."""

    def __init__(self) -> None:
        self.counts = [0, 0, 0, 0]  # both, edited only, control only, neither

    def add(self, edited: bool, control: bool) -> None:
        self.counts[(not edited) * 2 + (not control)] += 1

    @property
    def n(self) -> int:
        return sum(self.counts)

    @property
    def failures(self) -> int:
        return self.counts[0] + self.counts[1]

    @property
    def control_failures(self) -> int:
        return self.counts[0] + self.counts[2]

    def interval(self) -> tuple[float, float]:
        return newcombe_paired(*self.counts)


def _first(index: Index, task: int, key) -> Outcome | None:
    got = index.get((task, key))
    return got[0] if got else None


def _concept(
    p: Plan,
    slot: str,
    concept: str,
    cells: Sequence[SweepCell],
    single: Index,
    base: dict[int, bool],
) -> ConceptDamage:
    """The trials of every cell of slot.concept on the distinct tasks where the object is
    there (of its presence: the presence cells, and the look cells where the object is
    absent), each paired with its task unedited."""
    table = _Paired()
    devs: list[float] = []
    group = []
    for c in cells:
        if c.slot != slot or c.is_pair:
            continue
        mine = False
        for d, task in enumerate(p.distinct):
            outs = single.get((d, c.key), ())
            if not outs:
                continue
            obj = task.scene.obj(slot)
            adds = c.concept != PRESENCE and not obj.present
            if adds and c.value == obj.value(c.concept):
                continue  # adding it as it is: the presence cell's own trials
            if concept == PRESENCE:
                if not (c.concept == PRESENCE or adds):
                    continue
            elif c.concept != concept or adds:
                continue
            mine = True
            for o in outs:
                devs += [o.deviation] if math.isfinite(o.deviation) else []
                if _counted(o):
                    table.add(o.failed, base[d])
        if mine:
            group.append(c)
    ranked = sorted(group, key=_rank_key)
    return ConceptDamage(
        slot,
        concept,
        table.n,
        table.failures,
        wilson(table.failures, table.n),
        math.fsum(devs) / len(devs) if devs else math.nan,
        ranked[0].key if ranked and ranked[0].n else None,  # type: ignore[arg-type]
        table.control_failures,
        table.interval(),
    )
