"""The results folder of `dfa experiment unplanted`: tasks.csv and saliency.csv (every run's
rows; a run replaces the rows of its world, policy and kind), runs.json (each run's command and
cost) and table.md, rebuilt from all of them."""

from __future__ import annotations

import csv
import io
import json
import statistics
from collections.abc import Sequence
from pathlib import Path

from dfa_viz.experiment.explain import READOUTS
from dfa_viz.experiment.unplanted import NONE, SALIENCY_COLUMNS, TASK_COLUMNS
from dfa_viz.records import world_order
from policy.methods import METHOD_NAMES, METHODS
from search.stats import wilson
from search.unplanted import KINDS
from sim.core import UserError, files

# the planted benchmark's figures this table is read against (docs/results/explain/table.md,
# README's learned-prior table)
PLANTED = (
    "On the planted benchmark (docs/results/explain, 247 distinct planted tasks) the search's "
    "first concept is on the planted cause's object on 99% (96-100) of tasks, the saliency "
    "readouts chosen on held-out tasks on 47-66% and the random order on 39%; the learned "
    "prior puts the first valid size-2 edit of a planted size-2 task at median rank 1 (90th "
    "percentile 1-3)."
)
ALPHA = 0.05  # a method is told from the random order only where an exact test could reach it


def _key(r: dict) -> tuple[str, str, str]:
    return (r["world"], r["policy"], r["kind"])


def _order(r: dict) -> tuple:
    """Rows and runs in the paper's world order, then by policy and kind (KINDS' order),
    whichever ran last."""
    return (*world_order(r["world"]), r["policy"], KINDS.index(r["kind"]))


def read_csv(path: Path, columns: Sequence[str]) -> list[dict]:
    if not path.exists():
        return []
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and tuple(rows[0]) != tuple(columns):
        raise UserError(f"{path} has other columns than this version writes; give a new --out")
    return rows


def _csv(rows: list[dict], columns: Sequence[str]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def merge(out: Path, rows: list[dict], sal: list[dict], run: dict) -> tuple[Path, ...]:
    """Replace the rows of the run's (world, policy, kind) in OUT and rebuild the table, under
    an exclusive lock on OUT/.lock (runs of other worlds may write the same folder)."""
    import fcntl

    out.mkdir(parents=True, exist_ok=True)
    with (out / ".lock").open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _merge(out, rows, sal, run)


def _merge(out: Path, rows: list[dict], sal: list[dict], run: dict) -> tuple[Path, ...]:
    key = (run["world"], run["policy"], run["kind"])
    tasks = [r for r in read_csv(out / "tasks.csv", TASK_COLUMNS) if _key(r) != key] + rows
    sals = [r for r in read_csv(out / "saliency.csv", SALIENCY_COLUMNS) if _key(r) != key] + sal
    runs_path = out / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    runs = [r for r in runs if (r["world"], r["policy"], r["kind"]) != key] + [run]
    return (
        files.write_text(out / "tasks.csv", _csv(tasks, TASK_COLUMNS)),
        files.write_text(out / "saliency.csv", _csv(sals, SALIENCY_COLUMNS)),
        files.write_text(runs_path, json.dumps(runs, indent=1) + "\n"),
        files.write_text(out / "table.md", table(tasks, sals, runs)),
    )


def rebuild(out: Path) -> Path:
    """table.md again from OUT's CSVs and runs.json (the same table the last run wrote, by this
    version of the code)."""
    tasks = read_csv(out / "tasks.csv", TASK_COLUMNS)
    sals = read_csv(out / "saliency.csv", SALIENCY_COLUMNS)
    runs = json.loads((out / "runs.json").read_text())
    return files.write_text(out / "table.md", table(tasks, sals, runs))


def _pct(k: int, n: int) -> str:
    if n == 0:
        return NONE
    lo, hi = wilson(k, n)
    return f"{100 * k / n:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) [{k}/{n}]"


def _ranks(values: list[int]) -> str:
    if not values:
        return NONE
    q = sorted(values)
    p90 = q[min(len(q) - 1, int(0.9 * len(q) + 0.5) - 1)] if len(q) > 1 else q[0]
    return f"{statistics.median(q):g} / {p90}"


def table(tasks: list[dict], sals: list[dict], runs: list[dict]) -> str:
    groups: dict[tuple[str, str, str], list[dict]] = {}
    runs = sorted(runs, key=_order)
    for r in sorted(tasks, key=_order):
        groups.setdefault(_key(r), []).append(r)
    lines = [
        "# Failures that were not planted: the search, saliency and the learned prior against "
        "exhaustive interventions",
        "",
        "Tasks (search/unplanted.py): **compound**, a training task with two atomic changes of "
        "the concept space on two different objects at once (a look, or an object added or "
        "removed), drawn at random with the seed; **moved**, the same on the world's position "
        "shift; **natural**, a training layout the policy fails as it is (nothing planted). "
        "Each is kept only where the policy fails and the scripted expert meets R'; all are "
        "distinct. The **ground truth** is exhaustive: every effective edit of size 1 and 2 "
        "rolled out and judged by R'; the minimal edits under which the policy succeeds are "
        "the truth. Percentages over distinct tasks, 95% Wilson interval, [k/n].",
        "",
        "## Runs",
        "",
    ]
    for run in runs:
        lines.append(
            f"- `{run['command']}`: {run['tasks']} failing tasks from {run['candidates']} "
            f"candidates, {run['wall_s']:.0f} s (prior: {run['prior']})"
        )
    lines += [
        "",
        "## Ground truth",
        "",
        "| world | policy | kind | tasks | minimal size 1 | size 2 | none within 2 | minimal "
        "edits per task (median, max) | undoing the generator's changes is minimal | ... "
        "restores success |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (world, policy, kind), rows in groups.items():
        n = len(rows)
        sizes = [r["gt_size"] for r in rows]
        counts = [int(r["gt_count"]) for r in rows if r["gt_size"] != NONE]
        undo = [r for r in rows if r["undo_minimal"] != NONE]
        lines.append(
            f"| {world} | {policy} | {kind} | {n} | {sizes.count('1')} | {sizes.count('2')} | "
            f"{sizes.count(NONE)} | "
            + (f"{statistics.median(counts):g}, {max(counts)}" if counts else NONE)
            + f" | {_pct(sum(r['undo_minimal'] == '1' for r in undo), len(undo))} | "
            f"{_pct(sum(r['undo_restores'] == '1' for r in undo), len(undo))} |"
        )
    lines += [
        "",
        "## The counterfactual search (up to 2 changes, the world's defaults)",
        "",
        "It matches the demonstration, never reads R'. On tasks with a ground truth: its best "
        "edit is a minimal ground-truth edit; it restores success (any size up to 2); its size "
        "against the minimal one. On tasks without one: it still names an edit (none restores "
        "success). Rollouts: the search's median against the exhaustive ground truth's.",
        "",
        "| world | policy | kind | n | best edit is minimal truth | restores success | same "
        "size / larger / smaller / none | no truth: names an edit | rollouts (search / "
        "exhaustive) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (world, policy, kind), rows in groups.items():
        has = [r for r in rows if r["gt_size"] != NONE]
        lacking = [r for r in rows if r["gt_size"] == NONE]
        same = sum(r["cf_size"] == r["gt_size"] for r in has)
        larger = sum(r["cf_size"] != NONE and r["cf_size"] > r["gt_size"] for r in has)
        smaller = sum(r["cf_size"] != NONE and r["cf_size"] < r["gt_size"] for r in has)
        none = sum(r["cf_size"] == NONE for r in has)
        named = sum(r["cf_size"] != NONE for r in lacking)
        lines.append(
            f"| {world} | {policy} | {kind} | {len(has)} | "
            f"{_pct(sum(r['cf_in_gt'] == '1' for r in has), len(has))} | "
            f"{_pct(sum(r['cf_restores'] == '1' for r in has), len(has))} | "
            f"{same} / {larger} / {smaller} / {none} | {named} of {len(lacking)} | "
            f"{statistics.median(int(r['cf_rollouts']) for r in rows):g} / "
            f"{statistics.median(int(r['gt_rollouts']) for r in rows):g} |"
        )
    lines += [
        "",
        "## The learned prior",
        "",
        "Fitted on planted size-2 tasks (search/planted.py, seeds below 1,000,000; these tasks' "
        "seeds are 1,000,000 and up), or, in a run whose prior reads cross-fitted (Runs, "
        "`--prior-fit others`), each task's prior fitted on the run's other tasks (their size-1 "
        "passes labelled by their exhaustive ground truth), never on the task itself. On "
        "MiniGrid DoorKey a planted size-2 task is seldom one the expert can solve (a key opens "
        "only the door of its colour: 2 of the first 40 planted seeds), so the run fits on "
        "natural failures instead. Rank of the first minimal ground-truth edit among all "
        "edits of the minimal size, in the prior's order (its -log p summed over an edit's "
        "changes) and in plain enumeration order: median / 90th percentile.",
        "",
        "| world | policy | kind | n | prior rank | prior rank 1 | enumeration rank | edits of "
        "that size (median) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (world, policy, kind), rows in groups.items():
        has = [r for r in rows if r["prior_rank"] != NONE]
        prior = [int(r["prior_rank"]) for r in has]
        lines.append(
            f"| {world} | {policy} | {kind} | {len(has)} | {_ranks(prior)} | "
            f"{_pct(prior.count(1), len(has))} | "
            f"{_ranks([int(r['enum_rank']) for r in has])} | "
            + (f"{statistics.median(int(r['n_at_size']) for r in has):g}" if has else NONE)
            + " |"
        )
    lines += _saliency_tables(groups, sals)
    lines += ["", "## Against the planted benchmark", "", PLANTED, "", *_comparison(groups, sals)]
    return "\n".join(lines) + "\n"


def _saliency_tables(groups, sals: list[dict]) -> list[str]:
    names = {**METHOD_NAMES, "random": "Random"}
    hits: dict[tuple, list[int]] = {}
    for r in sals:
        hits.setdefault((*_key(r), r["method"], r["reading"], r["span"]), []).append(int(r["hit"]))
    out = [
        "",
        "## Saliency: object top-1 against the ground truth's objects (%)",
        "",
        "On tasks with a ground truth: the first concept of each readout (policy."
        "concept_saliency, the explainer benchmark's) belongs to an object a minimal "
        "ground-truth edit changes. An edit that adds an object has no pixels to point at. "
        "A dash: no row (no task with a ground truth, or a policy whose network does not "
        "declare what the methods need, policy.model.Explainable). The outside SB3 agent's "
        "network is taken apart like the project's own (policy.sb3_policy.SB3Actor: its "
        "logits from float frames, its features extractor's convolutions for Grad-CAM).",
    ]
    for reading, span in READOUTS:
        out += [
            "",
            f"### {'|attribution|' if reading == 'abs' else 'signed (blame)'}, "
            f"{'all steps' if span == 'all' else 'steps before the rollout diverges'}",
            "",
            "| world | policy | kind | "
            + " | ".join(names[m] for m in (*METHODS, "random"))
            + " |",
            "|---|---|---|" + "---|" * (len(METHODS) + 1),
        ]
        for key in groups:
            cells = []
            for m in (*METHODS, "random"):
                h = hits.get((*key, m, *((NONE, NONE) if m == "random" else (reading, span))), [])
                cells.append(_pct(sum(h), len(h)))
            out.append("| " + " | ".join(key) + " | " + " | ".join(cells) + " |")
    return out


def _comparison(groups, sals: list[dict]) -> list[str]:
    out = []
    floor: dict[tuple, list[int]] = {}
    for r in sals:
        if r["method"] == "random":
            floor.setdefault(_key(r), []).append(int(r["hit"]))
    for (world, policy, kind), rows in groups.items():
        has = [r for r in rows if r["gt_size"] != NONE]
        if not has:
            out.append(
                f"- {world} {kind}: no task has an edit of up to 2 changes that restores "
                "success; nothing here to name."
            )
            continue
        prior = [int(r["prior_rank"]) for r in has if r["prior_rank"] != NONE]
        at = f"{statistics.median(int(r['n_at_size']) for r in has):g}"
        text = (
            f"- {world} ({policy}) {kind}: {len(has)} of {len(rows)} failures have a ground "
            f"truth within 2 changes; the search's best edit is a minimal one on "
            f"{_pct(sum(r['cf_in_gt'] == '1' for r in has), len(has))}; "
            + (
                f"the learned prior's median rank {_ranks(prior).split(' / ')[0]} of {at}"
                if prior
                else "the learned prior not measured"
            )
        )
        random = floor.get((world, policy, kind), [])
        if random:
            misses = len(random) - sum(random)
            text += f"; the random order's object top-1 is {_pct(sum(random), len(random))}" + (
                f" (it misses {misses}: even a method right on every task could not be told "
                f"from it, exact one-sided p {0.5**misses:.2g} at best)"
                if 0.5**misses > ALPHA
                else ""
            )
        out.append(text + ".")
    return out
