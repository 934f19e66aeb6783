"""uPlot traces for the page: action distance to the demonstration (current step marked) and
the finetuning loss curve. Each function returns (data, series, scales) for gui.add_uplot."""

from __future__ import annotations

import numpy as np
from viser import uplot

from search import compared_steps
from sim.core import Trajectory, World

COLOURS = {
    "failed": "#d9480f",
    "counterfactual": "#2f9e44",
    "finetuned": "#1c7ed6",
    "epsilon": "#868e96",
    "step": "#212529",
}


def distance(world: World, traj: Trajectory, demo: Trajectory) -> np.ndarray:
    """float64 (T,): per-step action distance to the demonstration (L1; 0/1 for discrete);
    NaN after the demonstration has ended (those steps are not compared)."""
    a = traj.actions.reshape(traj.horizon, -1).astype(np.float64)
    b = demo.actions.reshape(demo.horizon, -1).astype(np.float64)
    d = (a != b).any(axis=1).astype(np.float64) if world.discrete else np.abs(a - b).sum(axis=1)
    d[compared_steps(world, demo) :] = np.nan
    return d


def distance_plot(
    world: World,
    demo: Trajectory | None,
    traces: dict[str, Trajectory | None],
    step: int,
):
    """Distances of each named rollout to the demonstration over steps, the search's bound,
    and a marker on every trace at `step` (the slider's step)."""
    horizon = world.horizon
    x = np.arange(horizon, dtype=np.float64)
    data: list[np.ndarray] = [x]
    series: list[uplot.Series] = [{"label": "step"}]
    top = 1.0
    if demo is not None:
        for name, traj in traces.items():
            if traj is None:
                continue
            d = distance(world, traj, demo)
            top = max(top, float(np.nanmax(d, initial=0.0)))
            data.append(d)
            series.append({"label": name, "stroke": COLOURS.get(name, "#495057"), "width": 2})
        if not world.discrete and world.epsilon > 0:
            data.append(np.full(horizon, world.epsilon))
            series.append(
                {"label": "ε", "stroke": COLOURS["epsilon"], "width": 1, "dash": (4.0, 4.0)}
            )
    lines = data[1:]
    marker = np.full(horizon, np.nan)
    t = min(step, horizon - 1)
    at_t = [float(v[t]) for v in lines if not np.isnan(v[t])]
    if at_t:
        marker[t] = max(at_t)
    data.append(marker)
    series.append(
        {
            "label": "now",
            "stroke": COLOURS["step"],
            "width": 0,
            "points": {"show": True, "size": 11, "fill": "#fab005", "width": 2},
        }
    )
    scales: dict[str, uplot.Scale] = {
        "x": {"time": False, "auto": False, "range": (-0.5, horizon - 0.5)},
        "y": {"auto": False, "range": (0.0, round(top * 1.1, 3))},
    }
    return tuple(data), tuple(series), scales


def loss_plot(losses: list[float] | tuple[float, ...], steps: int):
    """The finetuning loss over gradient steps (grows while the job runs), log scale."""
    y = np.maximum(np.asarray(losses, np.float64), 1e-9) if len(losses) else np.ones(1)
    x = np.arange(len(y), dtype=np.float64)
    series: tuple[uplot.Series, ...] = (
        {"label": "step"},
        {"label": "loss", "stroke": COLOURS["finetuned"], "width": 2},
    )
    scales: dict[str, uplot.Scale] = {
        "x": {"time": False, "auto": False, "range": (0.0, float(max(steps - 1, 1)))},
        "y": {"auto": True, "distr": 3, "log": 10},
    }
    return (x, y), series, scales
