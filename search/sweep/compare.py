"""The searches (search.sweep.strategies) measured on one outcome table: how many rollouts
each spends to confirm half, 90% and all of the failure modes, and how many it confirms per
1,000 rollouts within a share of the table's rollouts; means over seeds with 95% t intervals
for the stochastic ones."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from search.stats import t_interval
from search.sweep.strategies import Strategy
from search.sweep.table import OutcomeTable, Trace, trace

MILESTONES = (0.5, 0.9, 1.0)


@dataclass(frozen=True)
class Figure:
    """A mean over seeds and its 95% t interval (one seed: the interval is the value)."""

    mean: float
    low: float
    high: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Figure:
        return cls(*t_interval(values))


@dataclass(frozen=True)
class StrategyRun:
    """One search on one table over its seeds."""

    name: str
    seeds: int
    budget: int
    """Rollouts the per-1,000 rate is read at (a share of the table's)."""
    per_1000: Figure
    """Modes confirmed within `budget` rollouts, per 1,000 rollouts."""
    to: tuple[Figure, ...]
    """Rollouts to confirm each MILESTONES share of the modes."""
    false_alarms: Figure
    """Edits it confirmed on its own trials that the whole table does not."""
    curve: tuple[float, ...]
    """Mean modes confirmed after each rollout, up to the table's rollouts."""


def run_strategy(
    table: OutcomeTable, name: str, strategy: Strategy, seeds: Sequence[int], budget_share: float
) -> StrategyRun:
    traces: list[Trace] = [trace(table, strategy(table, s)) for s in seeds]
    budget = max(1, round(budget_share * table.rollouts))
    modes = len(table.modes)
    to = []
    for share in MILESTONES:
        k = math.ceil(share * modes)
        got = [tr.rollouts_to(k) for tr in traces]
        to.append(Figure.of([float(g) for g in got if g is not None]))
    curves = np.zeros((len(traces), table.rollouts))
    for j, tr in enumerate(traces):
        n = min(len(tr.found), table.rollouts)
        curves[j, :n] = tr.found[:n]
        curves[j, n:] = tr.found[n - 1] if n else 0
    return StrategyRun(
        name,
        len(seeds),
        budget,
        Figure.of([tr.found_by(budget) * 1000 / budget for tr in traces]),
        tuple(to),
        Figure.of([float(tr.false_alarms) for tr in traces]),
        tuple(float(v) for v in curves.mean(0)),
    )


def compare(
    table: OutcomeTable,
    strategies: Mapping[str, Strategy],
    *,
    seeds: int = 10,
    stochastic: Sequence[str] = (),
    budget_share: float = 0.25,
) -> tuple[StrategyRun, ...]:
    """Every strategy on the table: seeds 0..seeds-1 for those named in `stochastic`, seed 0
    alone for the others (their order does not depend on it)."""
    return tuple(
        run_strategy(table, name, s, range(seeds) if name in stochastic else range(1), budget_share)
        for name, s in strategies.items()
    )


__all__ = ["MILESTONES", "Figure", "StrategyRun", "compare", "run_strategy"]
