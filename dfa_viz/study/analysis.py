"""`dfa study analyse DIR`: the study's answers scored and compared, beside the paper's.

Scoring (the paper's rule): an object shift is named right when the answer ticks the changed
concept of the changed object; a distractor when it ticks every look the new object shows (its
colour and shape; its presence where it has no looks); an `other` shift when the answer is
"the cause is not among these". truth.json says which concepts each task needs.

    accuracy    per world x shift kind x condition: right / answered, standard error
                sqrt(p (1 - p) / n) (the paper's error bars)
    chi2        per world, each condition against "none" (or the first condition): the 2 x 2
                table right/wrong x condition, Pearson's chi-squared with 1 degree of freedom
                (scipy.stats.chi2_contingency, no continuity correction)
    wilcoxon    per participant, the share of "yes, it matters" on TR tasks against that on TI
                tasks (scipy.stats.wilcoxon, two-sided; only participants who had both)
    rejection   the share of TR answers saying it matters (the paper: 79%)

Writes DIR/analysis/answers.csv, accuracy.md, accuracy.png and answers.rrd.
"""

from __future__ import annotations

import csv
import io
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from dfa_viz.study.answers import Store
from dfa_viz.study.freeze import TRUTH, load_study, read_json
from sim import PAPER_WORLDS
from sim.core import UserError, files

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
    "duration_s",
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


def is_correct(truth: dict, selected, none: bool) -> bool:
    """The paper's rule (see the module's docstring)."""
    if truth["kind"] == "other":
        return none
    return not none and set(truth["required"]) <= set(selected)


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
                    "duration_s": a.duration_s,
                }
            )
    return rows


@dataclass(frozen=True)
class Cell:
    world: str
    kind: str
    condition: str
    n: int
    right: int

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
    files: list[Path] = field(default_factory=list)


def accuracy_cells(rows: list[dict]) -> list[Cell]:
    groups: dict[tuple[str, str, str], list[int]] = defaultdict(list)
    for r in rows:
        groups[(r["world"], r["kind"], r["condition"])].append(int(r["correct"]))
    return [Cell(w, k, c, len(v), sum(v)) for (w, k, c), v in sorted(groups.items())]


def chi2_tests(rows: list[dict], conditions: tuple[str, ...]) -> list[Chi2]:
    """Per world, each condition against the baseline (see the module's docstring)."""
    from scipy.stats import chi2_contingency

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
            except ValueError:  # a zero row or column: nothing to compare
                stat, p = math.nan, math.nan
            out.append(Chi2(world, c, base, stat, p))
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
    )


def _pct(x: float | None) -> str:
    return "–" if x is None or math.isnan(x) else f"{100 * x:.0f}%"


def _num(x: float) -> str:
    return "–" if math.isnan(x) else f"{x:.3g}"


def table_md(a: Analysis) -> str:
    lines = [
        "# Study results",
        "",
        f"{len({r['participant'] for r in a.rows})} participants, {len(a.rows)} answers, "
        f"{a.mean_duration_s:.1f} s per answer on average.",
        "",
        "## Naming the cause of the failure",
        "",
        "| world | shift | condition | n | accuracy ± SE | paper |",
        "|---|---|---|---|---|---|",
    ]
    for c in a.cells:
        paper = paper_accuracy(c.world, c.kind, c.condition)
        lines.append(
            f"| {c.world} | {c.kind} | {c.condition} | {c.n} | "
            f"{_pct(c.accuracy)} ± {100 * c.se:.0f} | {_pct(paper)} |"
        )
    lines += [
        "",
        "## Conditions compared (χ²(1), per world)",
        "",
        "| world | condition | against | χ² | p |",
        "|---|---|---|---|---|",
        *(
            f"| {t.world} | {t.condition} | {t.baseline} | {_num(t.chi2)} | {_num(t.p)} |"
            for t in a.chi2
        ),
        "",
        "## Should it matter (TR against TI)",
        "",
        f"TR answers saying it matters: {_pct(a.rejection)} (paper: {_pct(PAPER_REJECTION)}).  ",
        f"Wilcoxon signed-rank, TR against TI per participant ({a.pairs} pairs): "
        f"p = {_num(a.wilcoxon_p)} (paper: p < .001).",
        "",
    ]
    return "\n".join(lines)


def write_csv(path: Path, rows: list[dict]) -> Path:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return files.write_text(path, buf.getvalue())


def write_analysis(folder: Path) -> Analysis:
    """analyse(folder) and its files under folder/analysis/."""
    from dfa_viz.study.figures import write_plot, write_rrd

    folder = Path(folder)
    a = analyse(folder)
    out = folder / ANALYSIS
    out.mkdir(exist_ok=True)
    paths = [
        write_csv(out / "answers.csv", a.rows),
        files.write_text(out / "accuracy.md", table_md(a)),
        write_plot(out / "accuracy.png", a.cells),
        write_rrd(out / "answers.rrd", a),
    ]
    a.files.extend(paths)
    return a
