"""DAgger with the scripted expert as the labeller (policy.train.dagger, World.cloning's
dagger_rounds), on nav2d: seconds."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from policy.base import recipe
from policy.train import (
    TrainConfig,
    behaviour_clone,
    dagger,
    expert_relabelled,
    finetune,
    replayed,
    training_demos,
    training_tasks,
)
from sim.core import Cloning

QUICK = TrainConfig(steps=150)


def _error(world, policy, visited) -> float:
    """Mean L2 between the policy's actions and the expert's on the scenes `visited` holds."""
    obs = np.concatenate([v.observations[:-1] for v in visited])
    labels = np.concatenate([v.actions for v in visited])
    return float(np.linalg.norm(policy(obs) - labels, axis=1).mean())


def test_a_visited_rollout_is_labelled_by_the_expert(nav, nav_policy):
    task = nav.train_task(seed=3)
    visited = nav.rollout(task, nav_policy)
    labelled = expert_relabelled(nav, task, visited)
    assert labelled.scenes == visited.scenes
    assert np.array_equal(labelled.observations, visited.observations)
    want = [nav.expert_action(task, s) for s in visited.scenes[:-1]]
    assert np.array_equal(labelled.actions, np.stack(want))


def test_zero_rounds_is_plain_cloning_and_a_round_fits_the_scenes_the_policy_visits(nav):
    tasks = [nav.train_task(seed=i) for i in range(3)]
    demos = [nav.demonstrate(t) for t in tasks]
    plain, _ = behaviour_clone(nav, demos, config=QUICK)
    same, _ = dagger(nav, demos, tasks, rounds=0, config=QUICK)
    for a, b in zip(plain.net.state_dict().values(), same.net.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    visited = [
        expert_relabelled(nav, t, v)
        for t, v in zip(tasks, nav.rollout_batch(tasks, plain), strict=True)
    ]
    more, losses = dagger(nav, demos, tasks, rounds=1, config=QUICK)
    assert len(losses) == 2 * QUICK.steps and np.isfinite(losses).all()
    # measured 0.0023 against 0.0054 (a plain clone of 2 x steps: 0.0034)
    assert _error(nav, more, visited) < 0.75 * _error(nav, plain, visited)


def test_the_recipe_names_dagger_rounds_only_where_a_world_asks_for_them(nav):
    demos = training_demos(nav)[:2]
    assert "dagger_rounds" not in recipe(nav, demos, seed=0, config=QUICK)
    asking = type(
        "Asking", (type(nav),), {"cloning": dataclasses.replace(nav.cloning, dagger_rounds=2)}
    )
    assert recipe(asking(), demos, seed=0, config=QUICK)["dagger_rounds"] == 2
    assert Cloning().dagger_rounds == 0


def test_finetuning_replays_a_dagger_base_on_its_own_states_labelled_by_the_expert(nav, nav_policy):
    demos = training_demos(nav)
    assert replayed(nav, nav_policy, demos) == demos  # plain cloning: the demonstrations alone
    asking = type(
        "Asking", (type(nav),), {"cloning": dataclasses.replace(nav.cloning, dagger_rounds=1)}
    )()
    data = replayed(asking, nav_policy, demos)
    tasks = training_tasks(asking)
    assert data[: len(demos)] == demos and len(data) == len(demos) + len(tasks)
    visited = asking.rollout_batch(tasks, nav_policy)
    for task, rollout, labelled in zip(tasks, visited, data[len(demos) :], strict=True):
        assert labelled.scenes == rollout.scenes
        want = [asking.expert_action(task, s) for s in rollout.scenes[:-1]]
        assert np.array_equal(labelled.actions, np.stack(want))
    again = replayed(asking, nav_policy, demos)
    assert all(a is b for a, b in zip(again, data, strict=True))  # rolled out once


def test_finetuning_with_a_round_fits_the_scenes_the_finetuned_policy_visits(nav, nav_policy):
    shifted = [nav.test_task("object_ti", seed=i) for i in range(3)]
    demos = [nav.demonstrate(t) for t in shifted]
    tasks = [shifted[0].with_scene(d.scenes[0]) for d in demos]  # the starts, task 0's reward
    config = dataclasses.replace(QUICK, lr=5e-4)
    plain, _ = finetune(nav, nav_policy, demos, config=config)
    same, _ = finetune(nav, nav_policy, demos, config=config, rounds=0, task=shifted[0])
    for a, b in zip(plain.net.state_dict().values(), same.net.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    visited = [
        expert_relabelled(nav, t, v)
        for t, v in zip(tasks, nav.rollout_batch(tasks, plain), strict=True)
    ]
    more, losses = finetune(nav, nav_policy, demos, config=config, rounds=1, task=shifted[0])
    assert len(losses) == 2 * config.steps and np.isfinite(losses).all()
    # the round: the first fit again, on its own states labelled by the expert as well
    again, _ = behaviour_clone(
        nav, demos + visited, config=dataclasses.replace(config, seed=1), init=plain
    )
    for a, b in zip(again.net.state_dict().values(), more.net.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    # measured 0.0021 against 0.0030 (a plain finetune of 2 x steps: 0.0027), 1 and 2 threads
    assert _error(nav, more, visited) < _error(nav, plain, visited)
    assert nav_policy.net is not plain.net and nav_policy.net is not more.net  # base untouched
