"""CF H against Baseline H with one unit per seed: the inference under q2's table.md.

A seed draws the test task, the user's demonstration, the simulated users' answers and the
evaluation tasks once, for every budget of that seed, so the runs of one seed at different
budgets are not independent: the unit is the seed. Per seed and condition, the area under
success against finetuning trajectories (the trapezoid over the budgets run, divided by their
range: a mean success in [0, 1]); per row (world, shift), the seeds' differences CF H minus
Baseline H, tested with the exact one-sided Wilcoxon signed-rank test (search.stats), Holm's
correction over the rows tested, and a bootstrap interval over seeds of the mean difference.
A row is never called significant with fewer than MIN_SEEDS seeds that differ.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from search.stats import SignedRank, bootstrap_mean, holm, signed_rank_exact, units_for_power

ALPHA = 0.05
MIN_SEEDS = 10
"""Fewest seeds with a non-zero difference on which a row is tested at all."""
POWER = 0.8
BOOTSTRAP = 10_000


def area(curve: dict[int, float]) -> float:
    """Success against budget -> the area under it over the budgets' range, divided by that
    range (the trapezoid rule); with one budget, its success."""
    budgets = sorted(curve)
    if len(budgets) == 1:
        return curve[budgets[0]]
    ys = [curve[b] for b in budgets]
    return float(np.trapezoid(ys, budgets) / (budgets[-1] - budgets[0]))


@dataclass(frozen=True)
class SeedComparison:
    """CF H against Baseline H in one (world, shift), one area per seed and condition."""

    world: str
    shift: str
    budgets: tuple[int, ...]
    seeds: tuple[int, ...]
    cf: tuple[float, ...]
    baseline: tuple[float, ...]
    test: SignedRank
    interval: tuple[float, float]
    """95% bootstrap interval (over seeds) of the mean difference."""

    @property
    def diffs(self) -> tuple[float, ...]:
        return tuple(c - b for c, b in zip(self.cf, self.baseline, strict=True))

    @property
    def mean_diff(self) -> float:
        return float(np.mean(self.diffs))

    @property
    def tested(self) -> bool:
        """Whether any seed differs (a row where none does has nothing to test)."""
        return self.test.n > 0


def compare(rows: Sequence[dict[str, str]], world: str, shift: str) -> SeedComparison | None:
    """The seeds of (world, shift) that ran both conditions at the same budgets (None without
    any)."""
    curves: dict[tuple[str, int], dict[int, float]] = defaultdict(dict)
    for r in rows:
        if (r["world"], r["shift"]) == (world, shift) and r["condition"] in ("cf_h", "baseline_h"):
            curves[(r["condition"], int(r["seed"]))][int(r["budget"])] = float(r["success"])
    seeds = sorted(
        s
        for c, s in curves
        if c == "cf_h" and set(curves.get(("baseline_h", s), {})) == set(curves[(c, s)])
    )
    if not seeds:
        return None
    cf = tuple(area(curves[("cf_h", s)]) for s in seeds)
    base = tuple(area(curves[("baseline_h", s)]) for s in seeds)
    diffs = [c - b for c, b in zip(cf, base, strict=True)]
    return SeedComparison(
        world,
        shift,
        tuple(sorted(curves[("cf_h", seeds[0])])),
        tuple(seeds),
        cf,
        base,
        signed_rank_exact(diffs),
        bootstrap_mean(diffs, resamples=BOOTSTRAP, seed=0),
    )


def compare_all(
    rows: Sequence[dict[str, str]], pairs: Sequence[tuple[str, str]]
) -> list[tuple[SeedComparison, float | None]]:
    """Each (world, shift) with a comparison, and its Holm-adjusted p over the rows tested
    (None for a row where no seed differs)."""
    found = [c for w, s in pairs if (c := compare(rows, w, s)) is not None]
    tested = [c for c in found if c.tested]
    adjusted = dict(zip((id(c) for c in tested), holm([c.test.p for c in tested]), strict=True))
    return [(c, adjusted.get(id(c))) for c in found]


def verdict(c: SeedComparison, p_holm: float | None, m: int) -> str:
    """What the row may claim: never "significant" from fewer than MIN_SEEDS differing seeds."""
    if p_holm is None:
        return "no seed differs: nothing to test"
    if c.test.n < MIN_SEEDS:
        n, first = c.test.n, ALPHA / m
        reach = "cannot give p below" if c.test.p_min > first else "can give p as low as"
        return (
            f"too few seeds to test: {n} differ{'s' if n == 1 else ''}, fewer than {MIN_SEEDS}; "
            f"{n} {reach} 1/2^{n} = {_p(c.test.p_min)}, and Holm's first threshold is "
            f"0.05/{m} = {_p(first)}"
        )
    if p_holm <= ALPHA:
        return f"CF H > Baseline H at {ALPHA} after Holm over {m} rows"
    return f"not shown at {ALPHA} after Holm over {m} rows"


def _p(x: float) -> str:
    return f"{x:.3g}" if x >= 0.001 else f"{x:.2e}"


def markdown(rows: Sequence[dict[str, str]], pairs: Sequence[tuple[str, str]]) -> list[str]:
    """The section of table.md that tests CF H against Baseline H with one unit per seed (no
    lines when no row ran both)."""
    found = compare_all(rows, pairs)
    if not found:
        return []
    m = sum(p is not None for _, p in found)
    budgets = sorted({b for c, _ in found for b in c.budgets})
    lines = [
        "",
        "## CF H against Baseline H (simulated users), one unit per seed",
        "",
        "A seed draws the test task, the demonstration, the simulated users' answers and the "
        "evaluation tasks once for all its budgets, so a seed is one independent unit, not "
        "each (budget, seed) run. Per seed and condition: the area under success against "
        f"finetuning trajectories (trapezoid over {budgets[0]}–{budgets[-1]}, divided by "
        f"{budgets[-1] - budgets[0] or 1}: a mean success in [0, 1]). Per row: the seeds' "
        "differences CF H − Baseline H, their mean with a 95% bootstrap interval over seeds "
        f"({BOOTSTRAP} resamples, seeded), the exact one-sided Wilcoxon signed-rank p (zeros "
        "dropped, all 2^n signs of the n non-zero differences enumerated; n differences cannot "
        f"give less than 1/2^n) and Holm's correction over the {m} rows tested. A row with "
        f"fewer than {MIN_SEEDS} seeds that differ is not tested for significance. "
        f"*Seeds for {POWER:.0%} power*: the fewest seeds at which {MIN_SEEDS} or more differ "
        f"and the exact test gives p ≤ 0.05/{m} (Holm's first threshold) in {POWER:.0%} of "
        "samples drawn with "
        "replacement from this row's seed differences — a lower bound, since such samples "
        "never hold a seed unlike the observed ones.",
        "",
        "| world, shift | seeds | mean difference [95% bootstrap] | CF H ahead / behind / tied "
        "| exact p (smallest possible) | Holm p | verdict | seeds for 80% power |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c, p_holm in found:
        d = np.round(c.diffs, 9)
        counts = f"{int((d > 0).sum())} / {int((d < 0).sum())} / {int((d == 0).sum())}"
        need = units_for_power(c.diffs, alpha=ALPHA / max(1, m), power=POWER, min_nonzero=MIN_SEEDS)
        lines.append(
            f"| {c.world}, {c.shift} | {len(c.seeds)} | {c.mean_diff:+.2f} "
            f"[{c.interval[0]:+.2f}, {c.interval[1]:+.2f}] | {counts} | "
            + (f"{_p(c.test.p)} ({_p(c.test.p_min)})" if c.tested else "—")
            + f" | {'—' if p_holm is None else _p(p_holm)} | {verdict(c, p_holm, m)} | "
            + ("—" if need is None else str(need))
            + " |"
        )
    return lines


def row_line(rows: Sequence[dict[str, str]], world: str, shift: str) -> str | None:
    """One sentence for a row's own section: the seed-level mean difference and its interval."""
    c = compare(rows, world, shift)
    if c is None:
        return None
    return (
        f"CF H − Baseline H (simulated users), area under the curve per seed: "
        f"{c.mean_diff:+.2f} (95% bootstrap interval over {len(c.seeds)} seeds "
        f"{c.interval[0]:+.2f} to {c.interval[1]:+.2f}; {c.test.positive} seeds ahead, "
        f"{c.test.n - c.test.positive} behind, {len(c.seeds) - c.test.n} tied); the test is in "
        "the last section"
    )
