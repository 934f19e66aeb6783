"""The q2 results folder (folder.ResultsFolder) and the table of means beside the paper's.

    <out>/config.json   the settings every run shares (a folder keeps to one set)
    <out>/runs.csv      one row per finished run (runner.COLUMNS), resumable (folder.py)
    <out>/timings.csv   per run: its key, wall time and the worker that ran it (not part of the
                        results: it differs between executions)
    <out>/table.md      means and 95% confidence intervals beside the paper's numbers, and CF H
                        against Baseline H with one unit per seed (seed_test.py)
    <out>/plots/*.png, <out>/curves.rrd   (figures.py)

An interrupted experiment resumes from the folder: runs whose key is in runs.csv are skipped.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from dfa_viz.experiment import seed_test
from dfa_viz.experiment.conditions import (
    CONDITION_NAMES,
    CONDITIONS,
    condition_label,
    paper_value,
)
from dfa_viz.experiment.folder import ResultsFolder
from dfa_viz.experiment.runner import COLUMNS, KEY, Settings
from dfa_viz.records import world_order
from sim.core import files

TIMING_COLUMNS = (*KEY, "duration_s", "cpu_s", "host")
Key = tuple[str, str, str, int, int]

# two-sided 95% Student t quantiles by degrees of freedom (1..30); 1.96 beyond
_T95 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip


def key_of(row: dict[str, str]) -> Key:
    return (row["world"], row["shift"], row["condition"], int(row["budget"]), int(row["seed"]))


def results_folder(out: str | Path, settings: Settings) -> ResultsFolder:
    """The q2 experiment's folder: runs.csv, one row per run (its own unit)."""
    return ResultsFolder(
        out,
        settings.to_dict(),
        rows_file="runs.csv",
        columns=COLUMNS,
        timing_columns=TIMING_COLUMNS,
        key=key_of,
    )


# -- statistics -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Cell:
    """Success over seeds for one (world, shift, condition, budget)."""

    n: int
    mean: float
    half_width: float
    """Half-width of the 95% confidence interval of the mean (Student t); nan for n = 1."""

    @property
    def low(self) -> float:
        return max(0.0, self.mean - self.half_width) if self.n > 1 else self.mean

    @property
    def high(self) -> float:
        return min(1.0, self.mean + self.half_width) if self.n > 1 else self.mean


def summarise(values: Sequence[float]) -> Cell:
    n = len(values)
    mean = sum(values) / n
    if n == 1:
        return Cell(1, mean, math.nan)
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    t = _T95[n - 2] if n - 1 <= len(_T95) else 1.96
    return Cell(n, mean, t * sd / math.sqrt(n))


def cells(rows: Iterable[dict[str, str]]) -> dict[tuple[str, str, str, int], Cell]:
    """(world, shift, condition, budget) -> success over seeds."""
    groups: dict[tuple[str, str, str, int], list[float]] = defaultdict(list)
    for r in rows:
        groups[(r["world"], r["shift"], r["condition"], int(r["budget"]))].append(
            float(r["success"])
        )
    return {k: summarise(v) for k, v in sorted(groups.items())}


SOURCES = {
    "all": "the training demonstrations and the user's",
    "user": "the user's demonstration only",
}


def panels(table: dict[tuple[str, str, str, int], Cell]) -> list[tuple[str, str]]:
    """The (world, shift) pairs present, in the paper's order (object shifts first)."""
    pairs = {(w, s) for w, s, _, _ in table}
    return sorted(pairs, key=lambda p: (p[1] != "object", *world_order(p[0])))


def ordering(table, world: str, shift: str, budgets: Sequence[int]) -> str:
    """How our means compare with the paper's ordering: Oracle >= CF H > Baseline H at every
    budget, and CF H > NH-random at the two smallest budgets (ties counted apart)."""

    def means(*conditions: str, among: Sequence[int]) -> list[tuple[Cell, ...]]:
        out = []
        for b in among:
            got = [table.get((world, shift, c, b)) for c in conditions]
            if all(g is not None for g in got):
                out.append(tuple(got))
        return out

    def count(pairs: list[tuple[Cell, Cell]], strict: bool) -> str:
        ab = [(round(a.mean, 9), round(b.mean, 9)) for a, b in pairs]
        ok = sum(a > b if strict else a >= b for a, b in ab)
        ties = sum(a == b for a, b in ab) if strict else 0
        # a reversal outside the intervals: the first's upper end below the second's lower end
        against = sum(a.n > 1 and b.n > 1 and a.high < b.low for a, b in pairs)
        return (
            f"{ok}/{len(pairs)}"
            + (f" (tied at {ties})" if ties else "")
            + (f" (reversed beyond the 95% intervals at {against})" if against else "")
        )

    small = sorted(budgets)[:2]
    return (
        f"Oracle >= CF H at {count(means('oracle', 'cf_h', among=budgets), False)} budgets; "
        f"CF H > Baseline H at {count(means('cf_h', 'baseline_h', among=budgets), True)}; "
        f"CF H > NH-random at {count(means('cf_h', 'nh_random', among=small), True)} "
        "of the two smallest"
    )


def beyond_paper(table, world: str, shift: str) -> str | None:
    """Our CF H at 5 trajectories against the paper's CF H at 10 (None without a CF H at 5)."""
    ours = table.get((world, shift, "cf_h", 5))
    paper = paper_value(world, shift, "cf_h", 10)
    if ours is None or paper is None:
        return None
    met = "met" if round(ours.mean, 9) >= paper else "not met"
    return f"CF H at 5 trajectories {ours.mean:.2f} vs the paper's CF H at 10: {paper:g} ({met})"


SUCCESS_COLUMNS = ("success", "success_before", "success_all", "success_all_before")


def same_as_oracle(rows: Sequence[dict[str, str]]) -> tuple[int, int, int] | None:
    """(success columns equal, success columns and final loss equal, runs compared) of the CF H
    runs whose (world, shift, budget, seed) Oracle also ran; None without any."""
    oracle = {key_of(r)[:2] + key_of(r)[3:]: r for r in rows if r["condition"] == "oracle"}
    pairs = [
        (r, oracle[k])
        for r in rows
        if r["condition"] == "cf_h" and (k := key_of(r)[:2] + key_of(r)[3:]) in oracle
    ]
    if not pairs:
        return None
    equal = [all(a[c] == b[c] for c in SUCCESS_COLUMNS) for a, b in pairs]
    identical = [
        e and a["final_loss"] == b["final_loss"] for e, (a, b) in zip(equal, pairs, strict=True)
    ]
    return sum(equal), sum(identical), len(pairs)


def _fmt(cell: Cell | None, paper: float | None) -> str:
    ours = "—" if cell is None else f"{cell.mean:.2f}"
    if cell is not None and cell.n > 1:
        ours += f" ± {cell.half_width:.2f}"
    return ours + ("" if paper is None else f" ({paper:g})")


def markdown_table(rows: Sequence[dict[str, str]], settings: Settings) -> str:
    """One table per world and shift: our mean ± 95% CI half-width, the paper's in brackets."""
    table = cells(rows)
    seeds = sorted({int(r["seed"]) for r in rows})
    a = settings.finetuning
    lines = [
        "# Finetuning success versus finetuning trajectories",
        "",
        f"Mean success on {a.n_eval} fresh tasks that carry the test task's shift (its cause "
        "at accepted values no variant shows where there are enough, else as in the test task; "
        "on training layouts no finetuning trajectory starts from: runs.csv's eval_overlap and "
        "eval_layout_overlap, 0, and eval_distinct, the distinct scenes) over "
        f"{len(seeds)} seed(s) ± the "
        "half-width of its 95% confidence interval (Student t over seeds); the paper's number "
        f"in brackets. {len(rows)} runs; finetuning max({a.steps}, {a.steps_per_trajectory} "
        f"x budget) steps with {a.replay_share:.0%} of every batch replayed from the training "
        f"demonstrations; variants from {SOURCES[a.sources]}; counterfactual search up to "
        f"{settings.max_size} changes.",
        "",
        "Baseline H and CF H are **simulated users**, not people: they name the right concept "
        "at the rates the paper's participants did (without and with counterfactuals), "
        "otherwise another concept in the scene, and CF H only when the counterfactual search "
        "offered the right one.",
    ]
    same = same_as_oracle(rows)
    if same is not None:
        equal, identical, n = same
        right = sum(r["condition"] == "cf_h" and r["correct"] == "1" for r in rows)
        lines[-1] += (
            f" A simulated CF H user who is right runs Oracle's concept with Oracle's seed, so "
            f"that run is Oracle's bit for bit: CF H's success columns equal Oracle's in {equal} "
            f"of {n} (world, shift, budget, seed) runs, and the whole run (its final loss too) "
            f"in {identical} of {n} (the simulated user was right in {right} of {n}). Where "
            "the two agree, CF H's number is Oracle's and no separate evidence."
        )
    for world, shift in panels(table):
        budgets = sorted({b for w, s, _, b in table if (w, s) == (world, shift)})
        lines += [
            "",
            f"## {world}, {shift} shift",
            "",
            "| condition | " + " | ".join(str(b) for b in budgets) + " |",
            "|---|" + "---|" * len(budgets),
        ]
        for c in CONDITIONS:
            if not any((world, shift, c, b) in table for b in budgets):
                continue
            cols = [
                _fmt(table.get((world, shift, c, b)), paper_value(world, shift, c, b))
                for b in budgets
            ]
            lines.append(f"| {condition_label(c)} | " + " | ".join(cols) + " |")
        mine = [r for r in rows if (r["world"], r["shift"]) == (world, shift)]
        before = sum(float(r["success_before"]) for r in mine) / len(mine)
        before_all = sum(float(r["success_all_before"]) for r in mine) / len(mine)
        after_all = {
            c: sum(float(r["success_all"]) for r in mine if r["condition"] == c)
            / max(1, sum(r["condition"] == c for r in mine))
            for c in CONDITIONS
            if any(r["condition"] == c for r in mine)
        }
        overall = ", ".join(f"{CONDITION_NAMES[c]} {v:.2f}" for c, v in after_all.items())
        lines += [
            "",
            f"Base policy before finetuning: {before:.2f} on the shift ({before_all:.2f} over "
            "fresh tasks from all the user wants, training looks included; after finetuning, "
            f"mean over budgets: {overall}). "
            f"Ordering: {ordering(table, world, shift, budgets)}.",
        ]
        test = seed_test.row_line(rows, world, shift)
        if test:
            lines += ["", f"{test}."]
        goal = beyond_paper(table, world, shift)
        if goal:
            lines += ["", f"Beyond the paper: {goal}."]
    lines += seed_test.markdown(rows, panels(table))
    return "\n".join(lines) + "\n"


def write_table(out: Path, rows: Sequence[dict[str, str]], settings: Settings) -> Path:
    path = Path(out) / "table.md"
    files.write_text(path, markdown_table(rows, settings))
    return path
