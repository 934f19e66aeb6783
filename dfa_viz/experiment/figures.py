"""The experiment's figures: a PNG per world and shift, an overview PNG, and a .rrd of the curves.

Each panel draws what the paper's figure draws: success against finetuning trajectories for
the four conditions, our mean with its 95% confidence band, and the paper's curve dashed in the
same colour. Drawn with matplotlib's Agg canvas directly (no pyplot state, no display needed).
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dfa_viz.experiment.conditions import (
    CONDITIONS,
    PAPER_BUDGETS,
    condition_label,
    paper_value,
)
from dfa_viz.experiment.results import Cell, cells, panels
from dfa_viz.png import save_figure
from dfa_viz.rrd import RrdFile, send_blueprint

COLOURS = {  # RGB 0..255
    "nh_random": (127, 127, 127),
    "baseline_h": (31, 119, 180),
    "cf_h": (214, 39, 40),
    "oracle": (44, 160, 44),
}
APP_ID = "dfa-experiment-q2"


def _rgb01(c: str) -> tuple[float, float, float]:
    r, g, b = COLOURS[c]
    return (r / 255, g / 255, b / 255)


def _series(table, world: str, shift: str, condition: str) -> tuple[list[int], list[Cell]]:
    budgets = sorted(b for w, s, c, b in table if (w, s, c) == (world, shift, condition))
    return budgets, [table[(world, shift, condition, b)] for b in budgets]


def _draw_panel(ax, table, world: str, shift: str, *, legend: bool) -> None:
    for c in CONDITIONS:
        budgets, cs = _series(table, world, shift, c)
        colour = _rgb01(c)
        if budgets:
            mean = [x.mean for x in cs]
            ax.plot(budgets, mean, "o-", color=colour, lw=2, ms=4, label=condition_label(c))
            if any(x.n > 1 for x in cs):
                ax.fill_between(
                    budgets, [x.low for x in cs], [x.high for x in cs], color=colour, alpha=0.18
                )
        paper = [paper_value(world, shift, c, b) for b in PAPER_BUDGETS]
        ax.plot(PAPER_BUDGETS, paper, "--", color=colour, lw=1, alpha=0.7)
    ax.set_title(f"{world}, {shift} shift")
    ax.set_xlabel("finetuning trajectories")
    ax.set_ylabel("success")
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlim(0, max(105, max((b for w, s, _, b in table if (w, s) == (world, shift)))) + 5)
    ax.grid(alpha=0.3)
    if legend:
        ax.plot([], [], "--", color="black", lw=1, alpha=0.7, label="paper")
        ax.legend(loc="lower right", fontsize=8, frameon=False)


def write_plots(out: Path, rows: Sequence[dict[str, str]]) -> list[Path]:
    """plots/<world>-<shift>.png for each panel present, and plots/overview.png (all panels)."""
    from matplotlib.figure import Figure

    table = cells(rows)
    folder = Path(out) / "plots"
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    pairs = panels(table)
    for world, shift in pairs:
        fig = Figure(figsize=(4.2, 3.4))
        _draw_panel(fig.add_subplot(1, 1, 1), table, world, shift, legend=True)
        paths.append(folder / f"{world}-{shift}.png")
        save_figure(fig, paths[-1])
    if pairs:
        cols = min(3, len(pairs))
        rows_n = -(-len(pairs) // cols)
        fig = Figure(figsize=(4.2 * cols, 3.4 * rows_n))
        for i, (world, shift) in enumerate(pairs):
            _draw_panel(fig.add_subplot(rows_n, cols, i + 1), table, world, shift, legend=i == 0)
        fig.suptitle(
            "Success against finetuning trajectories (Baseline H and CF H: simulated users)",
            fontsize=11,
        )
        fig.tight_layout()
        paths.append(folder / "overview.png")
        save_figure(fig, paths[-1])
    return paths


def write_rrd(out: Path, rows: Sequence[dict[str, str]]) -> Path:
    """curves.rrd: per world/shift/condition the mean, the CI bounds and the paper's curve on a
    `budget` sequence timeline; one time-series view per world and shift."""

    table = cells(rows)
    path = Path(out) / "curves.rrd"
    rid = uuid.uuid5(uuid.NAMESPACE_URL, f"dfa/experiment/q2/{Path(out).name}")
    with RrdFile(path, rid, app_id=APP_ID) as rec:
        _log_curves(rec, table)
    return path


def _log_curves(rec, table) -> None:
    import rerun as rr
    import rerun.blueprint as rrb

    pairs = panels(table)
    send_blueprint(
        rec,
        rrb.Blueprint(
            rrb.Grid(
                *(
                    rrb.TimeSeriesView(
                        origin=f"/{world}/{shift}",
                        name=f"{world}, {shift} shift",
                        axis_y=rrb.ScalarAxis(range=(0.0, 1.0)),
                    )
                    for world, shift in pairs
                ),
                grid_columns=min(3, max(1, len(pairs))),
            ),
            collapse_panels=True,
        ),
    )

    def send(entity: str, budgets, values, name: str, colour, width: float) -> None:
        rec.log(entity, rr.SeriesLines(colors=[colour], widths=[width], names=[name]), static=True)
        rec.send_columns(
            entity,
            indexes=[rr.TimeColumn("budget", sequence=np.asarray(budgets, np.int64))],
            columns=rr.Scalars.columns(scalars=np.asarray(values, np.float64)),
        )

    for world, shift in pairs:
        for c in CONDITIONS:
            base, name, colour = f"{world}/{shift}/{c}", condition_label(c), COLOURS[c]
            budgets, cs = _series(table, world, shift, c)
            if budgets:
                send(f"{base}/mean", budgets, [x.mean for x in cs], name, colour, 2.5)
                if any(x.n > 1 for x in cs):
                    send(
                        f"{base}/ci_low",
                        budgets,
                        [x.low for x in cs],
                        f"{name} 95% low",
                        colour,
                        0.8,
                    )
                    send(
                        f"{base}/ci_high",
                        budgets,
                        [x.high for x in cs],
                        f"{name} 95% high",
                        colour,
                        0.8,
                    )
            paper = [paper_value(world, shift, c, b) for b in PAPER_BUDGETS]
            faded = tuple(int(v * 0.5 + 127) for v in colour)
            send(f"{base}/paper", PAPER_BUDGETS, paper, f"{name} (paper)", faded, 1.0)
