"""The sweep as text: sweep.csv (every cell, concept and pair, ranked by the difference from
the control arm) and the rich table printed in the terminal."""

from __future__ import annotations

import csv
import io
import math

from search.sweep import ConceptDamage, SweepCell, SweepResult, label

COLUMNS = (
    "kind",
    "rank",
    "label",
    "slot",
    "concept",
    "value",
    "applies",
    "counted",
    "unsolvable",
    "failures",
    "failure_rate",
    "failure_low",
    "failure_high",
    "deviation",
    "deviation_low",
    "deviation_high",
    "expert_deviation",
    "singles_rate",
    "excess",
    "example_seed",
    "example_edit",
    "example_pos",
    "worst",
    "control_failures",
    "control_rate",
    "success_rate_control",
    "difference",
    "difference_low",
    "difference_high",
)
SHOWN = 12  # cells in the terminal table


def _num(x: float) -> str:
    return "" if x != x else f"{x:.6g}"


def _counts(kind: str, rank: int, name: str, c: SweepCell | ConceptDamage) -> dict[str, str]:
    """The columns a cell and a concept share; the others empty."""
    row = dict.fromkeys(COLUMNS, "")
    row |= {
        "kind": kind,
        "rank": str(rank),
        "label": name,
        "counted": str(c.n),
        "failures": str(c.failures),
        "failure_rate": _num(c.failure_rate),
        "failure_low": _num(c.failure_ci[0]),
        "failure_high": _num(c.failure_ci[1]),
        "deviation": _num(c.deviation),
        "control_failures": str(c.control_failures),
        "control_rate": _num(c.control_rate),
        "success_rate_control": _num(1 - c.control_rate),
        "difference": _num(c.difference),
        "difference_low": _num(c.difference_ci[0]),
        "difference_high": _num(c.difference_ci[1]),
    }
    return row


def cell_row(kind: str, rank: int, c: SweepCell) -> dict[str, str]:
    ex = c.example
    row = _counts(kind, rank, c.label, c)
    if kind == "single":
        row |= {"slot": c.slot, "concept": c.concept, "value": c.value}
    else:
        row["excess"] = _num(c.excess)
    row |= {
        "applies": str(c.applies),
        "unsolvable": str(c.unsolvable),
        "deviation_low": _num(c.deviation_ci[0]),
        "deviation_high": _num(c.deviation_ci[1]),
        "expert_deviation": _num(c.expert_deviation),
        "singles_rate": _num(c.singles_rate),
    }
    if ex is not None:
        row |= {"example_seed": str(ex.seed), "example_edit": str(ex.edit)}
        row["example_pos"] = "" if ex.pos is None else " ".join(map(_num, ex.pos))
    return row


def concept_row(rank: int, c: ConceptDamage) -> dict[str, str]:
    row = _counts("concept", rank, f"{c.slot}.{c.concept}", c)
    row |= {"slot": c.slot, "concept": c.concept}
    row["worst"] = "" if c.worst is None else label(c.worst)
    return row


def rows(result: SweepResult) -> list[dict[str, str]]:
    """Concepts ranked, every single cell ranked, then every pair by its excess."""
    out = [concept_row(i + 1, c) for i, c in enumerate(result.concepts)]
    out += [cell_row("single", i + 1, c) for i, c in enumerate(result.cells)]
    out += [cell_row("pair", i + 1, c) for i, c in enumerate(result.pairs)]
    return out


def csv_text(result: SweepResult) -> str:
    """sweep.csv: the header and rows(result)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows(result))
    return buf.getvalue()


def _rate(n: int, k: int, ci: tuple[float, float]) -> str:
    if not n:
        return "—"
    return f"{k / n:.0%} ({100 * ci[0]:.0f}–{100 * ci[1]:.0f})"


def _control(c: SweepCell | ConceptDamage) -> str:
    return "—" if not c.n else f"{c.control_rate:.0%}"


def _diff(c: SweepCell | ConceptDamage) -> str:
    """The difference from the control, in points, with its 95% interval."""
    if not c.n:
        return "—"
    lo, hi = c.difference_ci
    return f"{100 * c.difference:+.0f} ({100 * lo:+.0f} to {100 * hi:+.0f})"


def _dev(x: float, ci: tuple[float, float] | None = None) -> str:
    if x != x:
        return "—"
    return f"{x:.3f}" if ci is None or math.isnan(ci[0]) else f"{x:.2f} ({ci[0]:.2f}–{ci[1]:.2f})"


def tables(result: SweepResult, shown: int = SHOWN):
    """rich Tables: the concepts ranked, the most damaging cells, and any interactions."""
    from rich.table import Table

    concepts = Table(
        title="concepts, most damaging first (Δ: fails - control, the same tasks unedited; "
        "an absent object's looks count as adding it)",
        title_justify="left",
    )
    concepts.add_column("#", justify="right", no_wrap=True)
    concepts.add_column("slot.concept", no_wrap=True)
    concepts.add_column("fails % (95% CI)", no_wrap=True)
    concepts.add_column("control", justify="right", no_wrap=True)
    concepts.add_column("Δ pts (95% CI)", no_wrap=True)
    concepts.add_column("trials", justify="right", no_wrap=True)
    concepts.add_column("deviation", justify="right", no_wrap=True)
    concepts.add_column("worst edit", no_wrap=True)
    for i, c in enumerate(result.concepts):
        concepts.add_row(
            str(i + 1),
            f"{c.slot}.{c.concept}",
            _rate(c.n, c.failures, c.failure_ci) if c.n else "— (none here)",
            _control(c),
            _diff(c),
            str(c.n),
            _dev(c.deviation),
            "" if c.worst is None else label(c.worst),
        )
    worst = _cells(
        f"the {shown} most damaging single edits (by Δ, largest first)", result.cells[:shown]
    )
    out = [concepts, worst]
    if result.interactions:
        pairs = result.interactions[:shown]
        title = "pairs that fail more often than both alone (by how much more, largest first)"
        out.append(_cells(title, pairs))
    return out


def _cells(title: str, cells) -> object:
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    table.add_column("#", justify="right")
    table.add_column("edit", no_wrap=True)
    table.add_column("fails % (95% CI)", no_wrap=True)
    table.add_column("control", justify="right", no_wrap=True)
    table.add_column("Δ pts (95% CI)", no_wrap=True)
    if cells and cells[0].is_pair:
        table.add_column("alone", justify="right", no_wrap=True)
    table.add_column("trials", justify="right", no_wrap=True)
    table.add_column("deviation", justify="right", no_wrap=True)
    for i, c in enumerate(cells):
        alone = [f"≤ {c.singles_rate:.0%}"] if c.is_pair else []
        table.add_row(
            str(i + 1),
            c.label,
            _rate(c.n, c.failures, c.failure_ci),
            _control(c),
            _diff(c),
            *alone,
            str(c.n),
            _dev(c.deviation),
        )
    return table


def summary(result: SweepResult, wall_s: float) -> str:
    """One line: what was swept, how much, how fast."""
    return (
        f"{result.world} · {result.policy}: {len(result.cells)} single edits"
        + (f" and {len(result.pairs)} pairs" if result.pairs else "")
        + f" on {result.tasks} tasks ({result.distinct} distinct; the policy fails "
        f"{result.base_failures} of those unedited): {result.rollouts} rollouts, "
        f"{result.frames} frames in {wall_s:.1f} s"
    )
