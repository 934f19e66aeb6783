"""`dfa study analyse DIR`: the study's answers scored and compared, beside the paper's.

Scoring (the paper's rule): an object shift is named right when the answer ticks the changed
concept of the changed object; a distractor when it names the new object (its presence, the
planted cause, or any of its looks); an `other` shift when the answer is "the cause is not
among these". truth.json says the cause and the concepts each task needs. Beside "includes the
cause", each answer is scored for an exact match (it ticks the cause and nothing else: the
changed concept; the distractor's presence or exactly its looks; for `other`, "none" alone) and
its precision (the share of its ticks that name the cause), so that ticking everything does not
score as knowing.

    accuracy    per world x shift kind x condition: right / answered, standard error
                sqrt(p (1 - p) / n) (the paper's error bars)
    chi2        per world, each condition against "none" (or the first condition): the 2 x 2
                table right/wrong x condition, Pearson's chi-squared with 1 degree of freedom
                (scipy.stats.chi2_contingency, no continuity correction), and beside it
                Fisher's exact test (scipy.stats.fisher_exact, two-sided), the one to read
                when a cell's expected count is under 5
    wilcoxon    per participant, the share of "yes, it matters" on TR tasks against that on TI
                tasks (scipy.stats.wilcoxon, two-sided; only participants who had both)
    rejection   the share of TR answers saying it matters (the paper: 79%)
    kept together   a mixed-effects logistic model (participant and task random) and an exact
                conditional test with tasks as strata (models.py): what to read in a within
                design, where one participant answers under every condition
    provenance  how many answers came through the study page, in how many page sessions, and
                the distribution of the seconds spent per question (durations.png)

Writes DIR/analysis/answers.csv, accuracy.md, accuracy.png, durations.png and answers.rrd.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dfa_viz.study import models
from dfa_viz.study.answers import Store
from dfa_viz.study.freeze import TRUTH, load_study, read_json
from sim import PAPER_WORLDS
from sim.core import UserError

ANALYSIS = "analysis"
COLUMNS = (
    "participant",
    "number",
    "position",
    "world",
    "kind",
    "shift",
    "relevance",
    "condition",
    "task",
    "selected",
    "none",
    "matters",
    "correct",
    "exact",
    "precision",
    "duration_s",
    "via",
    "session",
)
WORLD_ORDER = PAPER_WORLDS
# the paper's accuracies (Figure 4): kind -> (without, with counterfactuals) per world
PAPER = {
    "object": {"none": (0.28, 0.12, 0.03), "counterfactual": (0.97, 0.93, 0.94)},
    "distractor": {"none": (0.14, 0.32, 0.09), "counterfactual": (0.94, 0.88, 0.93)},
    "other": {"none": (0.36, 0.32, 0.22), "counterfactual": (0.82, 0.78, 0.82)},
}
PAPER_REJECTION = 0.79


def paper_accuracy(world: str, kind: str, condition: str) -> float | None:
    if world not in WORLD_ORDER or condition not in PAPER.get(kind, {}):
        return None
    return PAPER[kind][condition][WORLD_ORDER.index(world)]


def names_cause(truth: dict, concept: str) -> bool:
    """Whether ticking `concept` names the task's cause: the changed concept of an object
    shift; any concept of the added object of a distractor shift."""
    if truth["kind"] == "distractor":
        return concept.split(".")[0] == truth["cause"].split(".")[0]
    return concept == truth["cause"]


def is_correct(truth: dict, selected, none: bool) -> bool:
    """The paper's rule, the cause included (see the module's docstring)."""
    if truth["kind"] == "other":
        return none
    if none:
        return False
    if truth["kind"] == "distractor":
        return any(names_cause(truth, c) for c in selected)
    return set(truth["required"]) <= set(selected)


def is_exact(truth: dict, selected, none: bool) -> bool:
    """The cause and nothing else (see the module's docstring)."""
    if truth["kind"] == "other":
        return none and not selected
    chosen = set(selected)
    if none or not chosen:
        return False
    return chosen in ({truth["cause"]}, set(truth["required"]))


def precision(truth: dict, selected, none: bool) -> float:
    """The share of the ticked concepts that name the cause (NaN when none is ticked)."""
    if truth["kind"] == "other" or none or not selected:
        return math.nan
    return sum(names_cause(truth, c) for c in selected) / len(selected)


def answer_rows(folder: Path) -> list[dict]:
    """Every answer of every participant, joined with its task's truth (answers.csv's rows)."""
    folder = Path(folder)
    protocol, _ = load_study(folder)
    truth = read_json(folder / TRUTH)
    rows = []
    for pid, number, questions, answers in Store(folder, protocol).everyone():
        for a in answers:
            q = questions[a.position]
            t = truth.get(a.task)
            if t is None:
                raise UserError(f"{folder}: participant {pid} answered unknown task {a.task}")
            rows.append(
                {
                    "participant": pid,
                    "number": number,
                    "position": a.position,
                    "world": q.slot.world,
                    "kind": t["kind"],
                    "shift": t["shift"],
                    "relevance": t["relevance"] or "",
                    "condition": q.condition,
                    "task": a.task,
                    "selected": " ".join(a.selected),
                    "none": int(a.none),
                    "matters": int(a.matters),
                    "correct": int(is_correct(t, a.selected, a.none)),
                    "exact": int(is_exact(t, a.selected, a.none)),
                    "precision": _ratio(precision(t, a.selected, a.none)),
                    "duration_s": a.duration_s,
                    "via": a.via,
                    "session": a.session,
                }
            )
    return rows


def _ratio(x: float) -> str:
    return "" if math.isnan(x) else f"{x:.4g}"


@dataclass(frozen=True)
class Cell:
    world: str
    kind: str
    condition: str
    n: int
    right: int
    exact: int = 0
    precision: float = math.nan
    """The mean precision of the answers that ticked a concept (NaN when none did)."""

    @property
    def accuracy(self) -> float:
        return self.right / self.n

    @property
    def se(self) -> float:
        p = self.accuracy
        return math.sqrt(p * (1 - p) / self.n)


@dataclass(frozen=True)
class Chi2:
    world: str
    condition: str
    baseline: str
    chi2: float
    p: float
    fisher_p: float = math.nan
    small: bool = False
    """Some cell's expected count is under 5: read Fisher's exact p, not the chi-squared's."""


@dataclass(frozen=True)
class Analysis:
    rows: list[dict]
    cells: list[Cell]
    chi2: list[Chi2]
    wilcoxon_p: float
    """NaN when fewer than one participant had both TI and TR answers, or all differences are 0."""
    pairs: int
    rejection: float
    """Share of TR answers saying it matters (NaN without TR answers)."""
    mean_duration_s: float
    design: str = "between"
    mixed: models.MixedFit | None = None
    exact: list[models.Stratified] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)


def accuracy_cells(rows: list[dict]) -> list[Cell]:
    groups: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    for r in rows:
        groups[(r["world"], r["kind"], r["condition"])].append(r)
    cells = []
    for (w, k, c), v in sorted(groups.items()):
        shares = [float(r["precision"]) for r in v if r["precision"] != ""]
        cells.append(
            Cell(
                w,
                k,
                c,
                len(v),
                sum(int(r["correct"]) for r in v),
                sum(int(r["exact"]) for r in v),
                sum(shares) / len(shares) if shares else math.nan,
            )
        )
    return cells


def chi2_tests(rows: list[dict], conditions: tuple[str, ...]) -> list[Chi2]:
    """Per world, each condition against the baseline (see the module's docstring)."""
    from scipy.stats import chi2_contingency, fisher_exact

    base = "none" if "none" in conditions else conditions[0]
    out = []
    for world in dict.fromkeys(r["world"] for r in rows):

        def table(c, world=world):
            v = [int(r["correct"]) for r in rows if r["world"] == world and r["condition"] == c]
            return [sum(v), len(v) - sum(v)]

        for c in conditions:
            if c == base:
                continue
            t = [table(c), table(base)]
            try:
                res = chi2_contingency(t, correction=False)
                stat, p = float(res.statistic), float(res.pvalue)
                small = bool((res.expected_freq < 5).any())
            except ValueError:  # a zero row or column: nothing to compare
                stat, p, small = math.nan, math.nan, True
            exact = float(fisher_exact(t).pvalue) if sum(map(sum, t)) else math.nan
            out.append(Chi2(world, c, base, stat, p, exact, small))
    return out


def matters_pairs(rows: list[dict]) -> list[tuple[float, float]]:
    """Per participant with both: (share saying it matters on TR tasks, the same on TI)."""
    by: dict[str, dict[str, list[int]]] = defaultdict(lambda: {"TR": [], "TI": []})
    for r in rows:
        if r["relevance"] in ("TR", "TI"):
            by[r["participant"]][r["relevance"]].append(int(r["matters"]))
    return [
        (sum(d["TR"]) / len(d["TR"]), sum(d["TI"]) / len(d["TI"]))
        for d in by.values()
        if d["TR"] and d["TI"]
    ]


def wilcoxon_p(pairs: list[tuple[float, float]]) -> float:
    from scipy.stats import wilcoxon

    if not pairs or all(a == b for a, b in pairs):
        return math.nan
    tr, ti = zip(*pairs, strict=True)
    return float(wilcoxon(tr, ti, alternative="two-sided").pvalue)


def analyse(folder: Path) -> Analysis:
    """Score every answer and run the tests; nothing written (see write_analysis)."""
    protocol, _ = load_study(folder)
    rows = answer_rows(folder)
    if not rows:
        raise UserError(f"{folder}: no answers yet; run `dfa study serve {folder}` first")
    tr = [int(r["matters"]) for r in rows if r["relevance"] == "TR"]
    pairs = matters_pairs(rows)
    return Analysis(
        rows,
        accuracy_cells(rows),
        chi2_tests(rows, protocol.conditions),
        wilcoxon_p(pairs),
        len(pairs),
        sum(tr) / len(tr) if tr else math.nan,
        sum(float(r["duration_s"]) for r in rows) / len(rows),
        protocol.design,
        models.mixed_model(rows, protocol.conditions),
        models.stratified_exact(rows, protocol.conditions),
    )


def _pct(x: float | None) -> str:
    return "–" if x is None or math.isnan(x) else f"{100 * x:.0f}%"


def _num(x: float) -> str:
    return "–" if math.isnan(x) else f"{x:.3g}"


def provenance(rows: list[dict]) -> str:
    """Where the answers came from and how long they took (a paragraph of accuracy.md)."""
    page = [r for r in rows if r["via"] == "page"]
    sessions = len({r["session"] for r in page})
    secs = np.array([float(r["duration_s"]) for r in rows])
    q1, median, q3 = np.percentile(secs, [25, 50, 75])
    other = len(rows) - len(page)
    return (
        f"Provenance: {len(page)} of {len(rows)} answers came through the study page, in "
        f"{sessions} page session(s)"
        + (f"; {other} did not (written by other code, or before answers said)" if other else "")
        + f". Time on a question: median {median:.1f} s (quartiles {q1:.1f}–{q3:.1f} s, "
        f"range {secs.min():.1f}–{secs.max():.1f} s); their distribution: durations.png."
    )


def table_md(a: Analysis) -> str:
    lines = [
        "# Study results",
        "",
        f"{len({r['participant'] for r in a.rows})} participants, {len(a.rows)} answers, "
        f"{a.mean_duration_s:.1f} s per answer on average; {a.design}-subject design.",
        "",
        provenance(a.rows),
        "",
        "## Naming the cause of the failure",
        "",
        "Accuracy: the answer includes the cause (the paper's rule). Exact: the cause and "
        "nothing else. Precision: the share of an answer's ticks that name the cause.",
        "",
        "| world | shift | condition | n | accuracy ± SE | paper | exact | precision |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in a.cells:
        paper = paper_accuracy(c.world, c.kind, c.condition)
        lines.append(
            f"| {c.world} | {c.kind} | {c.condition} | {c.n} | "
            f"{_pct(c.accuracy)} ± {100 * c.se:.0f} | {_pct(paper)} | "
            f"{_pct(c.exact / c.n)} | {_pct(c.precision)} |"
        )
    lines += [
        "",
        "## Conditions compared (per world)",
        "",
        "χ²(1) as the paper reports it; Fisher's exact p beside it, the one to read where a "
        "cell's expected count is under 5 (marked *).",
        "",
        "| world | condition | against | χ² | p | Fisher's exact p |",
        "|---|---|---|---|---|---|",
        *(
            f"| {t.world} | {t.condition} | {t.baseline} | {_num(t.chi2)} | {_num(t.p)} | "
            f"{_num(t.fisher_p)}{' *' if t.small else ''} |"
            for t in a.chi2
        ),
        "",
        "## Should it matter (TR against TI)",
        "",
        f"TR answers saying it matters: {_pct(a.rejection)} (paper: {_pct(PAPER_REJECTION)}).  ",
        f"Wilcoxon signed-rank, TR against TI per participant ({a.pairs} pairs): "
        f"p = {_num(a.wilcoxon_p)} (paper: p < .001).",
    ]
    if a.mixed is not None and len({r["condition"] for r in a.rows}) > 1:
        lines += models.markdown(a.mixed, a.exact, a.design)
    lines.append("")
    return "\n".join(lines)
