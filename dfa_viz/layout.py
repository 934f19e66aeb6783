"""The layout a reviewer first sees in a run's recording (its blueprint): the rollouts side
by side titled with ✓ or ✗, the distances and actions beneath (a tab per action dimension,
or per action of a discrete world, named by the world), the texts in a row of their own,
then the variants and the charts. Titles are short enough to show whole."""

from __future__ import annotations

import numpy as np
import rerun.blueprint as rrb

from dfa_viz.run_record import RunRecord
from policy.methods import METHOD_NAMES
from search import distance_to_demo
from sim.core import Trajectory, World

ROLLOUTS = ("failed", "demonstration", "counterfactual", "finetuned")
AUGMENTED_SHOWN = 2  # variants given a view of their own (all are recorded): 2 tiles are
# wide enough for "variant 1 of 40" at 1400 px (4 cut "variant 1" to "varian")


def _mark(traj: Trajectory | None) -> str:
    return "" if traj is None else (" ✓" if traj.success else " ✗")


def rollout_titles(record: RunRecord) -> dict[str, str]:
    """Each rollout's view title, with ✓ or ✗ for whether it did what the user wants."""
    d, ad = record.diagnosis, record.adaptation
    cf = d.counterfactual if d is not None else None
    return {
        "failed": f"the policy{_mark(record.rollout)}",
        "demonstration": f"demonstration{_mark(record.demo)}",
        "counterfactual": f"after the edit{_mark(cf)}",
        "finetuned": f"finetuned{_mark(ad.rollout if ad else None)}",
    }


def blueprint(world: World, record: RunRecord, *, saliency: str | None = None) -> rrb.Blueprint:
    """What a reviewer sees first: the four rollouts side by side on one `step` timeline
    (paused at step 0), the action distance and the actions beneath, then the task, what
    changed, the feedback, the variants finetuned on, the loss and the success. saliency: the
    method whose layer lies over the failed rollout's frames (named in its title)."""
    titles = rollout_titles(record)
    if saliency is not None:
        titles["failed"] += f" · {METHOD_NAMES.get(saliency, saliency)}"
    views: list = [
        rrb.Spatial2DView(origin=f"rollouts/{name}", name=titles[name]) for name in ROLLOUTS
    ]
    if world.view3d is not None:
        from dfa_viz import scene3d

        views += scene3d.views(world.view3d)
    one_step = world.horizon == 1
    if one_step:  # one point per rollout: bars, not curves
        plots: list = [
            rrb.Spatial2DView(origin="charts/distance", name="distance to the demo"),
            rrb.Spatial2DView(origin="charts/candidates", name="edits the search tried"),
        ]
    else:
        plots = [
            rrb.TimeSeriesView(
                origin="action_distance",
                name="distance to the demo",
                plot_legend=rrb.PlotLegend("RightTop"),
                axis_y=rrb.ScalarAxis(range=(0.0, _distance_top(world, record))),
            ),
            rrb.TimeSeriesView(
                origin="search",
                contents=["search/candidates/**", "search/epsilon", "search/bound"],
                name="edits tried (green: kept)",
                plot_legend=rrb.PlotLegend(visible=False),
            ),
            rrb.Tabs(
                *(
                    rrb.TimeSeriesView(
                        origin="/",
                        contents=[f"rollouts/{name}/action/{k}" for name in ROLLOUTS],
                        name=label,
                    )
                    for k, label in enumerate(action_labels(world))
                ),
                name="actions",
            ),
        ]
    n_aug = len(record.adaptation.augmented) if record.adaptation else 0
    texts = [  # a row of their own: wide enough for every column of their tables
        rrb.TextDocumentView(origin="task", name="the task"),
        rrb.TextDocumentView(origin="edit", name="what changed"),
        rrb.TextDocumentView(origin="feedback", name="your feedback"),
    ]
    bottom: list = []
    if n_aug:
        bottom.append(
            rrb.Grid(
                *(
                    rrb.Spatial2DView(
                        origin=f"augmented/a{i:03d}", name=f"variant {i + 1} of {n_aug}"
                    )
                    for i in range(min(n_aug, AUGMENTED_SHOWN))
                ),
                name=f"variants ({n_aug})",
            )
        )
    bottom += [
        rrb.Spatial2DView(origin="charts/loss", name="finetuning loss"),
        rrb.Spatial2DView(origin="charts/success", name="success before → after"),
    ]
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(*views),
            rrb.Horizontal(*plots),
            rrb.Horizontal(*texts),
            rrb.Horizontal(*bottom),
            row_shares=[3, 2, 2, 2],
        ),
        rrb.TimePanel(timeline="step", play_state="paused", state="collapsed"),
        collapse_panels=True,
    )


def action_labels(world: World) -> tuple[str, ...]:
    """A name per action dimension, the world's own, else "action k"; a discrete world's
    actions are a dimension each (action_series: 1 at the steps that take it)."""
    return world.action_names or tuple(f"action {k}" for k in range(world.action_dim))


def action_series(world: World, actions: np.ndarray) -> np.ndarray:
    """float64 (T, A) to plot: a continuous world's actions as they are; a discrete world's
    int64 (T,) as one column per action, 1 at the steps that take it and 0 elsewhere."""
    if world.discrete:
        a = np.asarray(actions).reshape(-1)
        return (a[:, None] == np.arange(world.action_dim)[None, :]).astype(np.float64)
    return np.asarray(actions, np.float64).reshape(len(actions), -1)


def _distance_top(world: World, record: RunRecord) -> float:
    """The top of the distance plot: every rollout's largest distance, and epsilon."""
    top = world.epsilon if not world.discrete else 1.0
    if record.demo is None:
        return max(top, 1.0)
    trajs = [record.rollout, record.diagnosis.counterfactual if record.diagnosis else None]
    trajs.append(record.adaptation.rollout if record.adaptation else None)
    for traj in trajs:
        if traj is not None:
            top = max(top, float(np.nanmax(distance_to_demo(world, traj, record.demo), initial=0)))
    return round(1.1 * top, 3) or 1.0
