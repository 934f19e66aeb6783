"""The explanation benchmark's folder (folder.ResultsFolder) and the table of hit rates.

    <out>/config.json   the settings every job shares (a folder keeps to one set)
    <out>/tasks.csv     one row per (world, shift, seed, explainer, reading, span)
                        (explain.COLUMNS), resumable (folder.py)
    <out>/timings.csv   per explainer and task: the explainer's wall time on that task and
                        the worker (not part of the results: it differs between executions)
    <out>/table.md      hit rates over distinct tasks with 95% Wilson intervals, per readout;
                        time per task
    <out>/hits.png      (explain_figures.py)

A rate counts distinct tasks (explain.task_id), not rows: the rows of one task (seeds that drew
the same task; a world's TI and TR shifts, which share scenes) count once, with their mean hit
(the same for every explainer but the seeded tie-breaks and the random order).

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
    NONE,
    READOUTS,
    TIMING_COLUMNS,
    ExplainSettings,
    explainer_names,
    readouts_of,
)
from dfa_viz.experiment.folder import ResultsFolder
from dfa_viz.records import world_order
from search.stats import t_interval, wilson
from sim.core import files

METRICS = {
    "object_hit1": "object top-1",
    "hit1": "top-1",
    "hit3": "top-3",
}
"""The hit columns, the headline first: a map can name an object, not which of its concepts."""
READOUT_NAMES = {
    ("abs", "all"): "|attribution|, all steps",
    ("signed", "all"): "signed (pushes away from the demonstration), all steps",
    ("abs", "before"): "|attribution|, steps before the rollout diverges",
    ("signed", "before"): "signed, steps before the rollout diverges",
}


def row_key(row: Mapping[str, str]) -> tuple[str, str, int, str, str, str]:
    """A row's key; a timing's (one per explainer and task) has reading and span "-"."""
    return (
        row["world"],
        row["shift"],
        int(row["seed"]),
        row["explainer"],
        row.get("reading", NONE),
        row.get("span", NONE),
    )


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
        parts=sum(len(readouts_of(e)) for e in settings.explainers),
    )


# -- statistics -----------------------------------------------------------------------------------
def readout_rows(
    rows: Iterable[Mapping[str, str]], readout: tuple[str, str]
) -> list[Mapping[str, str]]:
    """The rows of one saliency readout, with the search's and the random order's one row."""
    return [r for r in rows if (r["reading"], r["span"]) in (readout, (NONE, NONE))]


def rates(
    rows: Iterable[Mapping[str, str]], metric: str
) -> dict[tuple[str, str, str], tuple[float, int]]:
    """(world, shift, explainer) -> (hits, distinct tasks) of a metric column (hit1, hit3,
    object_hit1) over rows of one readout: a task's hit is the mean over its rows; world and
    shift "all" pool over them, a task counted once."""
    got: dict[tuple[str, str, str], dict[tuple[str, str], list[int]]] = defaultdict(
        lambda: defaultdict(list)
    )
    for r in rows:
        task = (r["world"], r["task_id"])
        for key in (
            (r["world"], r["shift"], r["explainer"]),
            (r["world"], "all", r["explainer"]),
            ("all", "all", r["explainer"]),
        ):
            got[key][task].append(int(r[metric]))
    return {
        k: (sum(sum(h) / len(h) for h in tasks.values()), len(tasks)) for k, tasks in got.items()
    }


def half(task_id: str) -> int:
    """Which of two halves a task falls in (its id's parity)."""
    return int(task_id, 16) % 2


def held_out(
    rows: Sequence[Mapping[str, str]],
) -> tuple[list[Mapping[str, str]], dict[tuple[str, str], list[tuple[str, str]]]]:
    """The rows that score each saliency method with the readout chosen on held-out tasks:
    a world's tasks of one half (`half`) read as the readout with the most object top-1 hits
    on the other half (shifts pooled, distinct tasks; ties in READOUTS' order). Returns those
    rows (reading "chosen", span "-") with the search's and the random order's, and per (world,
    explainer) the readouts chosen for half 0 and half 1."""
    out = [r for r in rows if r["reading"] == NONE]
    picks: dict[tuple[str, str], list[tuple[str, str]]] = {}
    keys = dict.fromkeys((r["world"], r["explainer"]) for r in rows if r["reading"] != NONE)
    for world, e in keys:
        mine = [r for r in rows if (r["world"], r["explainer"]) == (world, e)]
        picks[(world, e)] = []
        for h in (0, 1):
            train = [r for r in mine if half(r["task_id"]) != h]
            score = {
                ro: rates(readout_rows(train, ro), "object_hit1").get((world, "all", e), (0, 0))
                for ro in READOUTS
            }
            best = max(
                READOUTS, key=lambda ro: (score[ro][0] / max(score[ro][1], 1), -READOUTS.index(ro))
            )
            picks[(world, e)].append(best)
            out += [
                {**r, "reading": "chosen", "span": NONE}
                for r in mine
                if half(r["task_id"]) == h and (r["reading"], r["span"]) == best
            ]
    return out, picks


def cell(k: float, n: int) -> str:
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
        key=lambda p: (world_order(p[0]), _rank(p[1], EXPLAIN_SHIFTS)),
    )
    return explainers, pairs


def _rank(value: str, order: Sequence[str]) -> tuple[int, str]:
    return (order.index(value) if value in order else len(order), value)


def markdown_table(
    rows: Sequence[Mapping[str, str]],
    timings: Sequence[Mapping[str, str]],
    settings: ExplainSettings,
) -> str:
    """Per metric and readout, one table: a row per world and shift, a column per explainer."""
    explainers, pairs = panel_order(rows)
    names = explainer_names()
    tasks = {(r["world"], r["shift"], r["seed"]) for r in rows}
    per = sorted({sum(1 for t in tasks if t[:2] == p) for p in pairs})
    m = f"{per[0]}" if len(per) == 1 else f"{per[0]}–{per[-1]}"
    distinct = len({(r["world"], r["task_id"]) for r in rows})
    lines = [
        "# Which concept broke the policy? Explanations against the planted cause",
        "",
        f"{len(tasks)} failing test tasks ({m} per world and shift, seeds 0 .. M-1; "
        f"{distinct} distinct tasks: seeds can draw the same task, and a world's TI and TR "
        "shifts share scenes), each the first task of its seed's stream that the committed "
        "base policy fails, with the scripted expert's demonstration. Each explainer ranks the "
        "concepts visible in the test scene. **Object top-1**, the headline: the first concept "
        "belongs to the cause's object (all a saliency map can tell apart: concepts of one "
        "object share its pixels and tie, broken at random, so concept top-1 caps a map at "
        "the share of its object's concepts); top-1 and top-3: the planted cause (as a person "
        'names it: "goal.shape", "lava.presence") ranked first or among the first three. '
        "Percent of **distinct** tasks (a task's rows count once, with their mean hit), 95% "
        "Wilson interval over the distinct tasks in brackets; n: distinct tasks. "
        f"Counterfactual search up to {settings.max_size} changes; saliency maps by captum "
        "over the failed rollout's steps against the demonstrated actions, read four ways "
        "from one set of maps: the attribution's magnitude or its sign (the object whose "
        "pixels push the action away from the demonstration most first) summed inside each "
        "object's pixels, over every step or over the steps before the rollout leaves the "
        "demonstration. The search and the random order have one reading, repeated in every "
        "table. The paper's users, with / without counterfactuals, named the shifted concept "
        "at the rates in the last column of the top-1 tables (its object and distractor "
        "shifts; TI and TR pooled); for a new distractor the paper counted an answer naming "
        "the distractor's looks as right, which is the object top-1 reading here.",
    ]
    chosen, picks = held_out(rows)
    lines += _rate_table(
        "Object top-1 hits (%), each method's readout chosen on held-out tasks",
        rates(chosen, "object_hit1"),
        explainers,
        pairs,
        names,
        False,
    )
    lines += [
        "",
        "The distinct tasks of each world are split in two halves by their task_id; each "
        "half is scored with the readout that has the best object top-1 on the other half "
        "(the world's shifts pooled; ties in the order of the tables below). Chosen (for "
        "the halves 0 / 1): "
        + "; ".join(
            f"{w} {names[e]} {' / '.join(f'{r}, {s}' for r, s in got)}"
            for (w, e), got in picks.items()
        )
        + ".",
    ]
    for metric, title in METRICS.items():
        for readout in READOUTS:
            table = rates(readout_rows(rows, readout), metric)
            head = f"{title[0].upper()}{title[1:]} hits (%), {READOUT_NAMES[readout]}"
            lines += _rate_table(head, table, explainers, pairs, names, metric == "hit1")
    lines += mask_table(rows, explainers, pairs, names, settings)
    times = mean_times(timings)
    worlds = [*dict.fromkeys(w for w, _ in pairs), "all"]
    lines += [
        "",
        "## Time per task",
        "",
        "Wall seconds per task on one torch thread, mean (and the slowest task): the search "
        "for the counterfactual; for a saliency method its maps over the failed rollout plus "
        "the object masks they share (every readout comes from the same maps).",
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


def _rate_table(head, table, explainers, pairs, names, users: bool) -> list[str]:
    lines = [
        "",
        f"## {head}",
        "",
        "| world | shift | n | "
        + " | ".join(names[e] for e in explainers)
        + (" | paper's users (CF / no CF) |" if users else " |"),
        "|---|---|---|" + "---|" * len(explainers) + ("---|" if users else ""),
    ]
    for world, shift in [*pairs, *((w, "all") for w in dict.fromkeys(p[0] for p in pairs))]:
        got = [table.get((world, shift, e), (0, 0)) for e in explainers]
        n = max(g[1] for g in got)
        extra = (f" {paper_users(world, shift)} |" if shift != "all" else " |") if users else ""
        cols = " | ".join(cell(*g) for g in got)
        lines.append(f"| {world} | {shift} | {n} | {cols} |{extra}")
    got = [table.get(("all", "all", e), (0, 0)) for e in explainers]
    cols = " | ".join(cell(*g) for g in got)
    lines.append(f"| **all** | | {max(g[1] for g in got)} | {cols} |" + (" |" if users else ""))
    return lines


def task_means(
    rows: Iterable[Mapping[str, str]], column: str
) -> dict[tuple[str, str, str, str], list[float]]:
    """(world, explainer, reading, span) -> one value per distinct task of a numeric column:
    the mean over the task's rows (nan and "-" left out); the randomisation column reads its
    last correlation (every layer re-initialised) and, as column "randomised_top", its first."""
    got: dict[tuple, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        text = r[column if column != "randomised_top" else "randomised"]
        if text == NONE:
            continue
        values = text.split()
        value = float(values[0] if column == "randomised_top" else values[-1])
        if value == value:
            key = (r["world"], r["explainer"], r["reading"], r["span"])
            got[key][r["task_id"]].append(value)
    return {k: [sum(v) / len(v) for v in tasks.values()] for k, tasks in got.items()}


MASK_METRICS = {
    "mass_cause": "mass on the cause",
    "area_cause": "the cause's area",
    "mass_off": "mass off every object",
    "deletion": "deletion",
    "randomised_top": "ρ, head random",
    "randomised": "ρ, all random",
}


def mask_table(rows, explainers, pairs, names, settings: ExplainSettings) -> list[str]:
    """Per world and readout, each saliency method's means over distinct tasks of the checks
    against the ground-truth mask (explain.MASK_COLUMNS), 95% t intervals for the mass."""
    means = {m: task_means(rows, m) for m in MASK_METRICS}
    maps = [
        e for e in explainers if any(r["explainer"] == e and r["reading"] != NONE for r in rows)
    ]
    lines = [
        "",
        "## Against the ground-truth mask",
        "",
        "Means over distinct tasks (95% t interval for the mass on the cause, clipped to "
        "0–1). *Mass on the cause*: Quantus' relevance mass accuracy, the share of the map's "
        "mass (the magnitude; for the signed reading the positive blame, what pushes the "
        "action away) on the planted cause's pixels; *the cause's area*: its share of the "
        "pixels, what a uniform map scores. *Mass off every object*: on pixels of no object "
        "(background, walls and the agent, which no world marks). *Deletion*: the action "
        "distance to the demonstration with 1/64 .. 1/4 of each frame's pixels set black in "
        "the readout's order, over the distance on the whole frames (below 1: deleting what "
        "the map points at brings the action closer; the random order's row deletes pixels at"
        " random). *ρ*: Spearman's correlation between the map and the map of the policy with"
        " its top layer (head random) or every layer (all random) re-initialised, on the "
        "first "
        f"{settings.sanity_steps} steps, over the pixels either map gives a non-zero value "
        "(near 1: the map does not depend on what the policy learned).",
        "",
        "| world | explainer | reading | steps | n | " + " | ".join(MASK_METRICS.values()) + " |",
        "|---|---|---|---|---|" + "---|" * len(MASK_METRICS),
    ]
    for world in dict.fromkeys(w for w, _ in pairs):
        for e in [*maps, "random"]:
            for readout in READOUTS if e != "random" else ((NONE, NONE),):
                key = (world, e, *readout)
                n = len(means["deletion"].get(key, []))
                if n == 0:
                    continue
                cols = []
                for m in MASK_METRICS:
                    values = means[m].get(key, [])
                    if not values:
                        cols.append("—")
                    elif m == "mass_cause":
                        mean, lo, hi = t_interval(values)  # a share: clipped to [0, 1]
                        cols.append(f"{mean:.2f} ({max(lo, 0.0):.2f}–{min(hi, 1.0):.2f})")
                    else:
                        cols.append(f"{sum(values) / len(values):.2f}")
                reading, span = readout
                lines.append(
                    f"| {world} | {names[e]} | {reading} | {span} | {n} | "
                    + " | ".join(cols)
                    + " |"
                )
    return lines


def write_table(
    out: Path,
    rows: Sequence[Mapping[str, str]],
    timings: Sequence[Mapping[str, str]],
    settings: ExplainSettings,
) -> Path:
    path = Path(out) / "table.md"
    files.write_text(path, markdown_table(rows, timings, settings))
    return path
