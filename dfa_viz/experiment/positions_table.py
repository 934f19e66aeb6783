"""The table (Markdown) and figure (PNG) of `dfa experiment positions`, from every world's
JSON in its folder."""

from __future__ import annotations

from pathlib import Path

from dfa_viz.records import figure_text, load_records
from sim.core import files

NAMES = {"uniform": "uniform sampling", "surrogate": "random-forest surrogate (FATE-style)"}


def _fig(f: dict, digits: int = 1) -> str:
    return figure_text(f, digits, to=" to ", grouped=False)


def table_md(records: list[dict]) -> str:
    lines = [
        "# Failures beyond single concepts: continuous scene parameters",
        "",
        "Each world declares continuous scene parameters its concept space does not enumerate "
        "(World.scene_parameters: nav2d the goal's and the agent's start x and y in its units, "
        "the tabletop the object's and the goal's centre in metres). A probe is one rollout "
        "of the policy on a training task with every parameter moved by up to the spread "
        "(a share of its range) from the task's own value; a point that would make objects "
        "overlap is drawn again. A failure: the policy fails the task's R' where the world's "
        "expert succeeds from the same scene. Both searches have the same budget, the same "
        "tasks and the same neighbourhoods; per seed each draws its own points. Failures per "
        "100 rollouts and distinct failing cells per 100 rollouts (a cell: the task and a "
        "grid of 20 bins over each parameter's range): mean over seeds with its 95% t "
        "interval; the gain is the surrogate's failures per 100 rollouts less uniform's, "
        "paired by seed.",
        "",
        "| world | search | seeds | budget | failures per 100 rollouts | distinct cells per 100 "
        "| gain over uniform |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in records:
        head = f"{r['world']} ({r['tasks']} tasks, spread {r['spread']})"
        for run in r["runs"]:
            gain = _fig(r["gain"]) if run["name"] == "surrogate" else ""
            lines.append(
                f"| {head} | {NAMES.get(run['name'], run['name'])} | {len(run['seeds'])} | "
                f"{r['budget']} | {_fig(run['failures'])} | {_fig(run['distinct'])} | {gain} |"
            )
            head = ""
    lines += [
        "",
        "## Diagnoses",
        "",
        "The first failures the surrogate found on seed 0 (the first in each distinct "
        "cell), each given to the counterfactual "
        "search with the expert's demonstration of the failing scene (edits of up to 2 "
        "concept changes; the world's candidate limit or the one given). The edit shown is "
        "the best ranked minimal edit whose rollout succeeds at the task; 'restores' says "
        "whether the policy, rolled out on the failing scene with it, succeeds.",
        "",
        "| world | task seed | parameters | minimal concept edit | restores | edits tried | s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in records:
        names = [p["name"] for p in r["parameters"]]
        for d in r["diagnoses"]:
            values = ", ".join(f"{n} {v:g}" for n, v in zip(names, d["values"], strict=True))
            edit = d["edit"] or f"none within size {d['max_size']}"
            if d["edit"] is None and not d["complete"]:
                edit += " (search stopped at its limit)"
            restores = "yes" if d["restores"] else "no" if d["edit"] else "–"
            lines.append(
                f"| {r['world']} | {d['task']} | {values} | {edit} | {restores} | {d['tried']} "
                f"| {d['seconds']:.1f} |"
            )
    lines += ["", "## Commands", ""]
    for r in records:
        secs = sum(s["seconds"] for run in r["runs"] for s in run["seeds"])
        diag = sum(d["seconds"] for d in r["diagnoses"])
        lines.append(f"- `{r['command']}` (searches {secs:.0f} s, diagnoses {diag:.0f} s)")
    return "\n".join(lines) + "\n"


def figure(records: list[dict]):
    """uint8 (H, W, 3): per world, the mean failures found against rollouts, one line per
    search."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * max(1, len(records)), 3.4), dpi=110)
    FigureCanvasAgg(fig)
    for k, r in enumerate(records):
        ax = fig.add_subplot(1, max(1, len(records)), k + 1)
        for run in r["runs"]:
            y = np.mean([s["curve"] for s in run["seeds"]], axis=0)
            ax.plot(np.arange(1, len(y) + 1), y, label=NAMES.get(run["name"], run["name"]))
        ax.set_title(f"{r['world']} (spread {r['spread']})", fontsize=9, loc="left")
        ax.set_xlabel("rollouts", fontsize=8)
        ax.set_ylabel("failures found (mean over seeds)", fontsize=8)
        ax.tick_params(labelsize=7)
        if k == 0:
            ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()  # type: ignore[attr-defined]


def write_summary(out: Path) -> None:
    from dfa_viz.sweep.figures import png_bytes

    records = load_records(out)
    files.write_text(out / "table.md", table_md(records))
    files.write_bytes(out / "failures.png", png_bytes(figure(records)))
