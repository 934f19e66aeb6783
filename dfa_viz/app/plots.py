"""uPlot traces for the page: action distance to the demonstration (current step marked) and
the finetuning loss curve. Each function returns (data, series, scales) for gui.add_uplot."""

from __future__ import annotations

import numpy as np
from viser import uplot

from dfa_viz.charts import COLOURS
from search import distance_to_demo
from sim.core import Trajectory, World


def distance_plot(
    world: World,
    demo: Trajectory | None,
    traces: dict[str, Trajectory | None],
    step: int,
    bound: float | None = None,
):
    """Distances of each named rollout to the demonstration over steps, the search's bound (ε,
    and `bound` where the search held edits under less: SearchResult.tightened), and a
    vertical line at `step` (the slider's step).

    Each label carries its series' value at that step ("failed 0.42", "step 7"): the legend is
    static (LEGEND), so hovering shows no value that is not a number where the line is absent.

    The line is drawn as its own series over a repeated x value: x is 0, 1, ..., step, step,
    ..., T-1 with every other series repeating its value there, and "now" set only at the two
    copies (0 and the top)."""
    horizon = world.horizon
    t = min(max(step, 0), horizon - 1)
    x = np.arange(horizon, dtype=np.float64)
    lines: list[np.ndarray] = []
    series: list[uplot.Series] = [{"label": "step"}]
    top = 1.0
    if demo is not None:
        for name, traj in traces.items():
            if traj is None:
                continue
            d = distance_to_demo(world, traj, demo)
            top = max(top, float(np.nanmax(d, initial=0.0)))
            lines.append(d)
            label = f"{name} {d[t]:.2f}" if np.isfinite(d[t]) else name
            series.append({"label": label, "stroke": COLOURS.get(name, "#495057"), "width": 2})
        bounds = [(f"ε {world.epsilon:g}", world.epsilon)] if world.epsilon > 0 else []
        if bound is not None:
            bounds.append((f"bound here {bound:.3f}", bound))
        for label, value in bounds if not world.discrete else []:
            lines.append(np.full(horizon, value))
            series.append(
                {"label": label, "stroke": COLOURS["epsilon"], "width": 1, "dash": (4.0, 4.0)}
            )
    top = round(top * 1.1, 3)
    at = np.insert(np.arange(horizon), t + 1, t)  # (T + 1,) index t twice
    now = np.full(horizon + 1, np.nan)
    now[t], now[t + 1] = 0.0, top
    data = (x[at], *(v[at] for v in lines), now)
    series.append({"label": f"step {t}", "stroke": COLOURS["step"], "width": 1.5})
    scales: dict[str, uplot.Scale] = {
        "x": {"time": False, "auto": False, "range": (-0.5, horizon - 0.5)},
        "y": {"auto": False, "range": (0.0, top)},
    }
    return data, tuple(series), scales


LEGEND: uplot.Legend = {"live": False}
"""The distance plot's legend: labels only (they carry the slider's step's values)."""

DISTANCE_AXES: tuple[uplot.Axis, ...] = (
    {"label": "step", "incrs": (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)},
    {"label": "action distance"},
)


def loss_plot(losses: list[float] | tuple[float, ...], steps: int):
    """The finetuning loss over gradient steps (grows while the job runs), on a log10 scale
    with ticks at whole powers of ten written out (1e-3, not 0)."""
    y = np.maximum(np.asarray(losses, np.float64), 1e-12) if len(losses) else np.ones(1)
    x = np.arange(len(y), dtype=np.float64)
    series: tuple[uplot.Series, ...] = (
        {"label": "step"},
        {"label": "loss", "stroke": COLOURS["finetuned"], "width": 2},
    )
    lo, hi = int(np.floor(np.log10(y.min()))), int(np.ceil(np.log10(y.max())))
    hi = max(hi, lo + 1)
    scales: dict[str, uplot.Scale] = {
        "x": {"time": False, "auto": False, "range": (0.0, float(max(steps - 1, 1)))},
        "y": {"auto": False, "distr": 3, "log": 10, "range": (10.0**lo, 10.0**hi)},
    }
    decades = tuple(10.0**k for k in range(lo, hi + 1))
    axes: tuple[uplot.Axis, ...] = (
        {"label": "finetuning step"},
        {"label": "loss", "splits": decades, "values": tuple(f"1e{k}" for k in range(lo, hi + 1))},
    )
    return (x, y), series, scales, axes
