"""`dfa bench`'s sweep rows: the physics bound is the world's own steps and renders the sweep
made, recorded and replayed alone; a sweep is held to 3x the larger of its bounds."""

from __future__ import annotations

import numpy as np

from dfa_viz.bench.physics import physics_bound_s, recorded
from dfa_viz.bench.sweep import MAX_TO_BOUND, bound_row
from policy import base_policy
from search.sweep import sweep, sweep_tasks
from sim import get_world


def test_the_physics_bound_replays_the_steps_and_renders_the_sweep_made():
    world = get_world("nav2d")
    policy = base_policy(world)
    todo = sweep_tasks(world, 4)
    with recorded(world) as calls:
        result = sweep(world, policy, todo)
    assert "step_batch" not in vars(world) and "render_batch" not in vars(world)
    # every policy rollout's first frame was rendered; every step given its scenes and actions
    assert calls.rendered >= result.rollouts and calls.stepped >= result.rollouts
    for scenes, actions in calls.steps:
        assert len(actions) == len(scenes)
        replayed = world.step_batch(scenes, actions)
        assert len(replayed) == len(scenes)
    assert physics_bound_s(world, calls, 1) > 0
    again = sweep(world, policy, todo)  # the recording changed nothing
    assert [(c.key, c.n, c.failures) for c in again.cells] == [
        (c.key, c.n, c.failures) for c in result.cells
    ]


def test_a_sweep_is_held_to_the_larger_of_its_bounds():
    assert get_world("tabletop").simulated and not get_world("nav2d").simulated
    r = {"frames": 100, "forward_per_s": 1000.0, "bound_s": 0.1, "to_forward": 40.0}
    slow = bound_row("tabletop", {**r, "physics_s": 2.0, "to_bound": 2.0}, _physics())
    assert slow[1:] == ("2.0x", f"<= {MAX_TO_BOUND:g}x", True)
    assert "physics bound (7 scenes stepped and 9 frames rendered" in slow[0]
    assert "40.0x the forward-pass bound" in slow[0]
    over = bound_row("nav2d", {**r, "physics_s": None, "to_bound": 3.5}, None)
    assert over[1:] == ("3.5x", "<= 3x", False) and "physics" not in over[0]


def _physics() -> dict:
    return {"physics_s": 2.0, "stepped": 7, "rendered": 9}


def test_recorded_actions_are_copies():
    world = get_world("nav2d")
    task = sweep_tasks(world, 1)[0]
    actions = np.asarray(world.expert_action(task, task.scene))[None] * 0
    scene = task.scene
    with recorded(world) as calls:
        world.step_batch([scene], actions)
    actions += 1
    assert (calls.steps[0][1] == 0).all()
