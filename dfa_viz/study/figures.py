"""The study's figures: accuracy bars and time on task (matplotlib PNGs), a .rrd of the answers.

accuracy.png: a panel per world (the paper's order), a group of bars per shift kind, a bar per
condition with its standard error; the paper's accuracies as black ticks where it has them.

durations.png: the distribution of the seconds spent per question, per condition.

answers.rrd (Rerun 0.41), on the `answer` timeline (answers in order of participants, then
questions): `answers/correct`, `answers/matters`, `answers/duration_s` (scalars) and
`answers/log` (one line per answer); static `study/results` (the Markdown table) and
`study/accuracy/<world>/<kind>/<condition>` (one scalar per cell at answer 0).
"""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr

from dfa_viz.png import save_figure
from dfa_viz.records import world_order
from dfa_viz.rrd import RrdFile
from dfa_viz.study.analysis import Analysis, Cell, paper_accuracy, table_md
from dfa_viz.study.protocol import CONDITIONS, KINDS

APP_ID = "dfa-study"
COLOURS = {"none": "#868e96", "counterfactual": "#2f9e44", "saliency": "#d9480f", "both": "#1c7ed6"}


def write_plot(path: Path, cells: list[Cell]) -> Path:
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    worlds = sorted({c.world for c in cells}, key=world_order)
    conds = [c for c in CONDITIONS if any(x.condition == c for x in cells)]
    kinds = [k for k in KINDS if any(x.kind == k for x in cells)]
    fig = Figure(figsize=(4.2 * len(worlds), 3.4))
    width = 0.8 / max(len(conds), 1)
    for i, world in enumerate(worlds):
        ax = fig.add_subplot(1, len(worlds), i + 1)
        for j, cond in enumerate(conds):
            for k, kind in enumerate(kinds):
                x = k - 0.4 + width * (j + 0.5)
                cell = next(
                    (c for c in cells if (c.world, c.kind, c.condition) == (world, kind, cond)),
                    None,
                )
                if cell is not None:
                    ax.bar(
                        x,
                        cell.accuracy,
                        width,
                        yerr=cell.se,
                        color=COLOURS[cond],
                        capsize=3,
                    )
                paper = paper_accuracy(world, kind, cond)
                if paper is not None:
                    ax.plot(
                        [x - width / 2, x + width / 2],
                        [paper, paper],
                        "k-",
                        lw=2,
                    )
        ax.set_xticks(np.arange(len(kinds)), kinds)
        ax.set_ylim(0, 1.05)
        ax.set_title(world)
        ax.set_ylabel("cause named right")
        ax.grid(axis="y", alpha=0.3)
        if i == 0:
            handles = [Patch(color=COLOURS[c], label=c) for c in conds]
            handles.append(Line2D([], [], color="k", lw=2, label="paper"))
            ax.legend(handles=handles, fontsize=8, frameon=False, loc="upper right")
    save_figure(fig, path)
    return Path(path)


def write_durations(path: Path, rows: list[dict]) -> Path:
    """durations.png: the seconds spent per question, a histogram per condition (log-spaced
    bins: a quick click and a long look both show), each answer's time as a tick below."""
    from matplotlib.figure import Figure

    secs = np.array([float(r["duration_s"]) for r in rows], np.float64)
    low, high = max(secs.min(), 0.1), max(secs.max(), 0.2)
    bins = np.geomspace(low * 0.9, high * 1.1, 25)
    conds = [c for c in CONDITIONS if any(r["condition"] == c for r in rows)]
    fig = Figure(figsize=(6.4, 3.4))
    ax = fig.add_subplot(1, 1, 1)
    for j, cond in enumerate(conds):
        mine = np.clip([float(r["duration_s"]) for r in rows if r["condition"] == cond], low, None)
        ax.hist(mine, bins=bins, color=COLOURS[cond], alpha=0.55, label=f"{cond} ({len(mine)})")
        ax.plot(mine, np.full(len(mine), -0.3 - 0.3 * j), "|", color=COLOURS[cond], ms=8)
    ax.set_xscale("log")
    ax.set_xlabel("seconds on the question (log scale)")
    ax.set_ylabel("answers")
    ax.set_title(f"Time on task: {len(secs)} answers, median {np.median(secs):.1f} s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, frameon=False)
    save_figure(fig, path)
    return Path(path)


def write_rrd(path: Path, a: Analysis) -> Path:
    rid = uuid.uuid5(uuid.NAMESPACE_URL, f"dfa-study/{len(a.rows)}/{a.rows[0]['participant']}")
    with RrdFile(path, rid, app_id=APP_ID) as rec:
        rec.log(
            "study/results", rr.TextDocument(table_md(a), media_type="text/markdown"), static=True
        )
        steps = rr.TimeColumn("answer", sequence=np.arange(len(a.rows)))
        for name in ("correct", "matters", "duration_s"):
            values = np.array([float(r[name]) for r in a.rows], np.float64)
            rec.log(f"answers/{name}", rr.SeriesLines(names=[name]), static=True)
            rec.send_columns(
                f"answers/{name}", indexes=[steps], columns=rr.Scalars.columns(scalars=values)
            )
        for i, r in enumerate(a.rows):
            rec.set_time("answer", sequence=i)
            what = r["selected"] or "not among these"
            rec.log(
                "answers/log",
                rr.TextLog(
                    f"{r['participant']} q{int(r['position']) + 1} {r['world']} {r['kind']} "
                    f"({r['condition']}): {what}; matters={bool(int(r['matters']))}; "
                    f"{'right' if int(r['correct']) else 'wrong'}"
                ),
            )
        rec.set_time("answer", sequence=0)
        for c in a.cells:
            rec.log(f"study/accuracy/{c.world}/{c.kind}/{c.condition}", rr.Scalars(c.accuracy))
    return Path(path)
