"""The sweep: every single concept edit (and, when asked, pairs of them) rolled out on many
tasks and judged by R': what breaks a policy before a user meets it.

A *cell* is one (slot, concept, value): on a task where the slot is there, the edit that
gives slot.concept that value; where the slot is absent, the edit that adds it with that
value (presence cells add or remove it as it is). Per cell: the failure rate of the policy
under R' (`world.success`) over the distinct tasks the cell applies to beside the control arm
(the same tasks unedited) and their difference, and its mean action deviation from the
unedited rollout (L1 per step for continuous actions, the share of steps whose action differs
for discrete ones), with 95% intervals (Wilson; Newcombe's paired; Student t). Cells are
ranked by the difference from the control.

Where the world has a scripted expert (a Benchmark), a failure counts only when R' can still
be met after the edit: the expert's demonstration of the unedited task, replayed on the edited
one, meets it, or else its own closed-loop demonstration does. Cells whose edit makes R'
unreachable (a removed key) say so instead of counting a failure against the policy.

Pure: nothing is logged or written; progress goes out through a callback. The work is cut
into units (groups of distinct tasks, each rolled out in lockstep through
`World.rollout_batch`) fixed by the tasks alone, so a unit gives the same outcomes whichever
process runs it: `sweep` runs them here, dfa_viz.sweep on a process pool or Ray.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

from policy.model import Policy
from search.sweep.cells import (
    CellKey,
    PairKey,
    added_slot,
    cell_edit,
    cell_keys,
    key_edit,
    label,
    pair_edit,
    sweep_tasks,
    task_of,
)
from search.sweep.result import ConceptDamage, Example, SweepCell, SweepResult, summarise
from search.sweep.units import (
    Outcome,
    Plan,
    Reference,
    Unit,
    UnitResult,
    moved,
    places,
    plan,
    run_unit,
)
from sim.core import PRESENCE, Task, World

PAIR_CELLS = 32  # pairs are tried among at most this many single cells

Runner = Callable[[Sequence[Unit]], list[UnitResult]]
# (what: "singles" | "pairs", units done, units in all) -> None
SweepProgress = Callable[[str, int, int], None]


def pair_keys(world: World, result: SweepResult, limit: int = PAIR_CELLS) -> tuple[PairKey, ...]:
    """The pairs to try: every two cells of different concepts among the `limit` most
    damaging cells (the largest difference from the control arm, then mean deviation) that do
    not always fail alone (a cell that always fails cannot fail more often paired), in the
    concept space's order."""
    order = {k: i for i, k in enumerate(cell_keys(world.space))}
    movers = [c for c in result.cells if c.n and c.failure_rate < 1.0]
    movers.sort(key=lambda c: (-c.difference, -_or(c.deviation, -1.0), order[c.first]))
    chosen = sorted((c.first for c in movers[:limit]), key=order.__getitem__)
    return tuple((a, b) for a, b in itertools.combinations(chosen, 2) if a[:2] != b[:2])


def _or(x: float, default: float) -> float:
    return default if x != x else x


def sweep(
    world: World,
    policy: Policy,
    tasks: Sequence[Task],
    *,
    sizes: tuple[int, ...] = (1,),
    pair_cells: int = PAIR_CELLS,
    expert: bool | None = None,
    policy_name: str = "",
    runner: Runner | None = None,
    on_progress: SweepProgress | None = None,
) -> SweepResult:
    """Every single cell on every task (and with size 2 in `sizes`, pairs: see `pair_keys`).

    runner: runs units and returns their results (default: one after another here, each
        through `run_unit`); dfa_viz.sweep passes one that runs them on a backend.
    """
    p = plan(tasks)
    if runner is None:

        def runner(units: Sequence[Unit]) -> list[UnitResult]:
            out = []
            for u in units:
                out.append(run_unit(world, policy, u, expert=expert))
                if on_progress is not None:
                    on_progress("pairs" if u.pairs else "singles", len(out), len(units))
            return out

    first = runner(p.units(world))
    result = summarise(world, p, first, policy=policy_name, sizes=sizes)
    keys = pair_keys(world, result, pair_cells) if 2 in sizes else ()
    if not keys:
        return result
    second = runner(p.units(world, keys))
    return summarise(world, p, first, policy=policy_name, pairs=second, sizes=sizes)


def failure_task(world: World, example: Example) -> Task:
    """The task an example failed on, as a task to diagnose: the seed's task with the edit
    made (the object it adds at the example's place); its cause is the concept the edit sets,
    presence when it adds or removes an object."""
    task = task_of(world, example.seed)
    scene = world.apply(moved(task.scene, example.edit, example.pos), example.edit)
    changes = example.edit.ordered
    slot = added_slot(example.edit)
    removed = next((c for c in changes if c.concept == PRESENCE), None)
    if slot is not None:
        cause = (slot, PRESENCE)
    elif removed is not None:
        cause = (removed.slot, PRESENCE)
    else:
        cause = (changes[0].slot, changes[0].concept)
    return Task(task.world, scene, task.reward, task.shift, task.seed, cause)


__all__ = [
    "PAIR_CELLS",
    "CellKey",
    "ConceptDamage",
    "Example",
    "Outcome",
    "PairKey",
    "Plan",
    "Reference",
    "SweepCell",
    "SweepProgress",
    "SweepResult",
    "Unit",
    "UnitResult",
    "added_slot",
    "cell_edit",
    "cell_keys",
    "failure_task",
    "key_edit",
    "label",
    "moved",
    "pair_edit",
    "pair_keys",
    "places",
    "plan",
    "run_unit",
    "summarise",
    "sweep",
    "sweep_tasks",
    "task_of",
]
