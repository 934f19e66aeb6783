"""Non-finite numbers never become an answer: a policy with NaN weights is refused wherever it
would be rolled out, searched or scored, and no world calls a non-finite state a success."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from policy import base_policy, finetune, score
from search import counterfactual_search
from sim import PAPER_WORLDS, get_world
from sim.core import UserError

WORLDS = list(PAPER_WORLDS)


def _nan_policy(world):
    policy = base_policy(world).copy()
    with torch.no_grad():
        policy.net.head[-1].weight[0, 0] = float("nan")
    return policy


@pytest.mark.parametrize("name", WORLDS)
def test_a_nan_weight_policy_is_refused_with_one_line(name):
    world = get_world(name)
    policy = _nan_policy(world)
    task = world.test_task("object_ti", 0)
    demo = world.demonstrate(task)
    for attempt in (
        lambda: world.rollout(task, policy),
        lambda: score(world, policy, task),
        lambda: counterfactual_search(world, policy, task.scene, demo),
    ):
        with pytest.raises(UserError, match="outputs are not finite numbers") as err:
            attempt()
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", WORLDS)
def test_no_world_calls_a_non_finite_state_a_success(name):
    """Take a successful demonstration and put one NaN into one of its states."""
    world = get_world(name)
    task = world.test_task("object_ti", 0)
    demo = world.demonstrate(task)
    assert world.success(task, demo.scenes)
    last = demo.scenes[-1]
    if last.agent:
        bad = dataclasses.replace(last, agent=(float("nan"), *last.agent[1:]))
        assert not world.success(task, [*demo.scenes[:-1], bad])
    goal = last.objects[0]
    moved = dataclasses.replace(goal, pos=(float("nan"), *goal.pos[1:]))
    assert not world.success(task, [*demo.scenes[:-1], last.with_obj(moved)])


def test_nan_actions_never_reach_a_success():
    nav = get_world("nav2d")
    task = nav.train_task()
    scene = task.scene
    for _ in range(nav.horizon):
        scene = nav.step_batch([scene], np.full((1, 2), np.nan, np.float32))[0]
    assert not nav.success(task, [task.scene, scene])
    table = get_world("tabletop")
    with pytest.raises(UserError, match="finite numbers"):
        table.step_batch([table.train_task().scene], np.full((1, 4), np.nan, np.float32))


def test_finetuning_stops_when_the_loss_is_not_finite():
    nav = get_world("nav2d")
    demo = nav.demonstrate(nav.train_task())
    bad = dataclasses.replace(demo, actions=np.full_like(demo.actions, np.nan))
    with pytest.raises(UserError, match="not finite"):
        finetune(nav, base_policy(nav), [bad])
    with pytest.raises(UserError, match="the loss is nan, not a finite number"):
        finetune(nav, _nan_policy(nav), [demo])
