"""The page's distance plot draws the bound the search held edits under: ε, and beside it the
failure's own largest distance where the failed rollout never left ε."""

from __future__ import annotations

import numpy as np

from dfa_viz.app.plots import distance_plot
from policy import failing_test_task
from search import counterfactual_search


def test_a_tightened_bound_is_drawn_beside_epsilon(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)  # a drift within ε
    demo = nav.demonstrate(task)
    result = counterfactual_search(nav, nav_policy, task.scene, demo)
    assert result.tightened
    traces = {"failed": nav.rollout(task, nav_policy)}
    data, series, _ = distance_plot(nav, demo, traces, 3, result.epsilon)
    labels = [s["label"] for s in series]
    assert labels[2:4] == ["ε 0.2", f"bound here {result.epsilon:.3f}"]
    assert np.allclose(data[3][~np.isnan(data[3])], result.epsilon)  # x, failed, ε, bound, step
    _, plain, _ = distance_plot(nav, demo, traces, 3)
    assert [s["label"] for s in plain][2:3] == ["ε 0.2"] and len(plain) == len(series) - 1
