"""The explanation benchmark's figure: hit rates per explainer, world and shift, as bars.

hits.png: a column of panels per world and a row per readout of the maps (explain.READOUTS),
each of object top-1, the headline; in each panel a group of bars per shift, one bar per
explainer with its 95% Wilson interval over distinct tasks; across each distractor group the
paper's users' rate of naming the distractor with counterfactuals (solid) and without (dotted),
which the paper scored as object top-1 is scored here. Drawn with matplotlib's Agg canvas
directly (no pyplot state).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from dfa_viz.experiment.conditions import ACCURACY
from dfa_viz.experiment.explain import READOUTS, explainer_names
from dfa_viz.experiment.explain_results import panel_order, rates, readout_rows
from dfa_viz.png import save_figure
from search.stats import wilson

COLOURS = {  # RGB 0..1
    "counterfactual": (0.84, 0.15, 0.16),
    "integrated_gradients": (0.12, 0.47, 0.71),
    "occlusion": (0.17, 0.63, 0.17),
    "grad_cam": (0.58, 0.40, 0.74),
    "kernel_shap": (1.00, 0.50, 0.05),
    "random": (0.55, 0.55, 0.55),
}


def write_plot(out: Path, rows: Sequence[Mapping[str, str]]) -> Path:
    """<out>/hits.png from the rows of tasks.csv."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    explainers, pairs = panel_order(rows)
    names = explainer_names()
    worlds = list(dict.fromkeys(w for w, _ in pairs))
    readings = {r: f"object top-1, {r[0]}, {r[1]} steps" for r in READOUTS}
    fig = Figure(figsize=(4.6 * len(worlds), 2.9 * len(readings) + 0.6))
    FigureCanvasAgg(fig)
    width = 0.8 / max(1, len(explainers))
    for row_i, (readout, title) in enumerate(readings.items()):
        table = rates(readout_rows(rows, readout), "object_hit1")
        for col, world in enumerate(worlds):
            ax = fig.add_subplot(len(readings), len(worlds), row_i * len(worlds) + col + 1)
            shifts = [s for w, s in pairs if w == world]
            for i, shift in enumerate(shifts):
                for j, e in enumerate(explainers):
                    k, n = table.get((world, shift, e), (0, 0))
                    if n == 0:
                        continue
                    lo, hi = wilson(k, n)
                    x = i - 0.4 + width * (j + 0.5)
                    ax.bar(x, k / n, width, color=COLOURS.get(e, (0, 0, 0)))
                    below, above = max(0.0, k / n - lo), max(0.0, hi - k / n)  # rounding
                    ax.errorbar(x, k / n, [[below], [above]], color="black", lw=0.8)
                acc = ACCURACY.get((world, shift.split("_")[0]))
                if acc is not None and shift.startswith("distractor"):
                    ax.hlines(acc[1], i - 0.45, i + 0.45, colors="black", lw=1.2)
                    ax.hlines(acc[0], i - 0.45, i + 0.45, colors="black", lw=1.2, linestyles=":")
            ax.set_xticks(range(len(shifts)), [s.replace("_", " ") for s in shifts], fontsize=8)
            ax.set_ylim(0, 1.05)
            ax.set_title(f"{world}, {title}", fontsize=10)
            ax.set_ylabel("share of tasks" if col == 0 else "")
            ax.grid(axis="y", alpha=0.3)
    handles = [Patch(color=COLOURS.get(e, (0, 0, 0)), label=names[e]) for e in explainers]
    cf = Line2D([], [], color="black", lw=1.2, label="paper's users with CF")
    no = Line2D([], [], color="black", lw=1.2, ls=":", label="paper's users, no CF")
    fig.legend(
        handles=[*handles, cf, no],
        loc="lower center",
        ncol=min(4, len(handles) + 2),
        fontsize=8,
        frameon=False,
    )
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    path = Path(out) / "hits.png"
    save_figure(fig, path, dpi=110, tight=False)
    return path
