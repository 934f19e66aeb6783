"""The explanation benchmark's folder (folder.ResultsFolder) and the table of hit rates.

    <out>/config.json   the settings every job shares (a folder keeps to one set)
    <out>/tasks.csv     one row per (world, shift, seed, explainer) (explain.COLUMNS),
                        resumable (folder.py)
    <out>/timings.csv   per row: its key, the explainer's wall time on that task and the worker
                        (not part of the results: it differs between executions)
    <out>/table.md      hit rates with 95% Wilson intervals, and time per task
    <out>/hits.png      (explain_figures.py)

An interrupted benchmark resumes from the folder: a task is done when every explainer has its
row.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from dfa_viz.experiment.args import EXPLAIN_SHIFTS
from dfa_viz.experiment.conditions import ACCURACY
from dfa_viz.experiment.explain import (
    COLUMNS,
    EXPLAINERS,
    TIMING_COLUMNS,
    ExplainSettings,
    explainer_names,
)
from dfa_viz.experiment.folder import ResultsFolder
from search.stats import wilson
from sim import PAPER_WORLDS
from sim.core import files

METRICS = {
    "hit1": "top-1",
    "hit3": "top-3",
    "object_hit1": "object top-1",
}


def row_key(row: Mapping[str, str]) -> tuple[str, str, int, str]:
    return (row["world"], row["shift"], int(row["seed"]), row["explainer"])


def explain_folder(out: str | Path, settings: ExplainSettings) -> ResultsFolder:
    """The benchmark's folder: tasks.csv, one row per explainer; a task is done when every
    explainer of the settings has its row."""
    return ResultsFolder(
        out,
        settings.to_dict(),
        rows_file="tasks.csv",
        columns=COLUMNS,
        timing_columns=TIMING_COLUMNS,
        key=row_key,
        unit=lambda r: (r["world"], r["shift"], int(r["seed"])),
        parts=len(settings.explainers),
    )


# -- statistics -----------------------------------------------------------------------------------
def rates(
    rows: Iterable[Mapping[str, str]], metric: str
) -> dict[tuple[str, str, str], tuple[int, int]]:
    """(world, shift, explainer) -> (hits, tasks) of a metric column (hit1, hit3, object_hit1);
    world and shift "all" pool over them."""
    out: dict[tuple[str, str, str], list[int]] = defaultdict(lambda: [0, 0])
    for r in rows:
        hit = int(r[metric])
        for key in (
            (r["world"], r["shift"], r["explainer"]),
            (r["world"], "all", r["explainer"]),
            ("all", "all", r["explainer"]),
        ):
            out[key][0] += hit
            out[key][1] += 1
    return {k: (v[0], v[1]) for k, v in out.items()}


def cell(k: int, n: int) -> str:
    """A rate in percent with its 95% Wilson interval: "94 (84–98)"."""
    if n == 0:
        return "—"
    lo, hi = wilson(k, n)
    return f"{100 * k / n:.0f} ({100 * lo:.0f}–{100 * hi:.0f})"


def mean_times(
    timings: Iterable[Mapping[str, str]],
) -> dict[tuple[str, str], tuple[float, float]]:
    """(world, explainer) -> (mean, max) wall seconds per task; world "all" pools the worlds."""
    got: dict[tuple[str, str], list[float]] = defaultdict(list)
    for t in timings:
        for world in (t["world"], "all"):
            got[(world, t["explainer"])].append(float(t["duration_s"]))
    return {k: (sum(v) / len(v), max(v)) for k, v in got.items()}


def paper_users(world: str, shift: str) -> str:
    """The paper's users naming the shifted concept, with / without counterfactuals (%)."""
    acc = ACCURACY.get((world, shift.split("_")[0]))
    return "" if acc is None else f"{100 * acc[1]:.0f} / {100 * acc[0]:.0f}"


def panel_order(rows: Sequence[Mapping[str, str]]) -> tuple[list[str], list[tuple[str, str]]]:
    explainers = [e for e in EXPLAINERS if any(r["explainer"] == e for r in rows)]
    pairs = sorted(
        {(r["world"], r["shift"]) for r in rows},
        key=lambda p: (_rank(p[0], PAPER_WORLDS), _rank(p[1], EXPLAIN_SHIFTS)),
    )
    return explainers, pairs


def _rank(value: str, order: Sequence[str]) -> tuple[int, str]:
    return (order.index(value) if value in order else len(order), value)


def markdown_table(
    rows: Sequence[Mapping[str, str]],
    timings: Sequence[Mapping[str, str]],
    settings: ExplainSettings,
) -> str:
    """Per metric, one table: a row per world and shift, a column per explainer."""
    explainers, pairs = panel_order(rows)
    names = explainer_names()
    tasks = {(r["world"], r["shift"], r["seed"]) for r in rows}
    per = sorted({sum(1 for t in tasks if t[:2] == p) for p in pairs})
    m = f"{per[0]}" if len(per) == 1 else f"{per[0]}–{per[-1]}"
    lines = [
        "# Which concept broke the policy? Explanations against the planted cause",
        "",
        f"{len(tasks)} failing test tasks ({m} per world and shift, seeds 0 .. M-1), "
        "each the first task of its seed's stream that the committed base policy fails, "
        "with the scripted expert's demonstration. Each explainer ranks the concepts visible "
        "in the test scene; a hit is the planted cause (as a person names it: "
        '"goal.shape", "lava.presence") ranked first (top-1) or among the first three '
        "(top-3); object top-1: the first concept belongs to the cause's object (all a "
        "saliency map can tell apart). Percent of tasks, 95% Wilson interval in brackets. "
        f"Counterfactual search up to {settings.max_size} changes; saliency maps by captum "
        "over the failed rollout's steps against the demonstrated actions, reduced to the "
        "attribution inside each object's pixels; concepts of one object tie (a map shows "
        "an object, not which of its concepts matters), broken at random. The paper's users, "
        "with / without counterfactuals, named the shifted concept at the rates in the last "
        "column (its object and distractor shifts; TI and TR pooled); for a new distractor "
        "the paper counted an answer naming the distractor's looks as right, which is the "
        "object top-1 reading here.",
    ]
    for metric, title in METRICS.items():
        table = rates(rows, metric)
        lines += [
            "",
            f"## {title[0].upper()}{title[1:]} hits (%)",
            "",
            "| world | shift | "
            + " | ".join(names[e] for e in explainers)
            + (" | paper's users (CF / no CF) |" if metric == "hit1" else " |"),
            "|---|---|" + "---|" * len(explainers) + ("---|" if metric == "hit1" else ""),
        ]
        for world, shift in [*pairs, *((w, "all") for w in dict.fromkeys(p[0] for p in pairs))]:
            cols = [cell(*table.get((world, shift, e), (0, 0))) for e in explainers]
            extra = ""
            if metric == "hit1":
                extra = f" {paper_users(world, shift)} |" if shift != "all" else " |"
            lines.append(f"| {world} | {shift} | " + " | ".join(cols) + " |" + extra)
        cols = [cell(*table.get(("all", "all", e), (0, 0))) for e in explainers]
        lines.append(
            "| **all** | | " + " | ".join(cols) + " |" + (" |" if metric == "hit1" else "")
        )
    times = mean_times(timings)
    worlds = [*dict.fromkeys(w for w, _ in pairs), "all"]
    lines += [
        "",
        "## Time per task",
        "",
        "Wall seconds per task on one torch thread, mean (and the slowest task): the search "
        "for the counterfactual; for a saliency method its maps over the failed rollout plus "
        "the object masks they share.",
        "",
        "| explainer | " + " | ".join(worlds) + " |",
        "|---|" + "---|" * len(worlds),
    ]
    for e in explainers:
        cols = [
            f"{times[(w, e)][0]:.3f} ({times[(w, e)][1]:.2f})" if (w, e) in times else "—"
            for w in worlds
        ]
        lines.append(f"| {names[e]} | " + " | ".join(cols) + " |")
    return "\n".join(lines) + "\n"


def write_table(
    out: Path,
    rows: Sequence[Mapping[str, str]],
    timings: Sequence[Mapping[str, str]],
    settings: ExplainSettings,
) -> Path:
    path = Path(out) / "table.md"
    files.write_text(path, markdown_table(rows, timings, settings))
    return path
