"""The committed FetchPickAndPlace base policy (policy/weights/fetch_FetchPickAndPlace-v4/):
trained with today's recipe, and it puts the block on the target in most held-out tasks of its
training distribution."""

from __future__ import annotations

import sim
from policy.train import replays_rollouts

PICK = "fetch:FetchPickAndPlace-v4"
HELD_OUT = range(1000, 1010)  # training-distribution tasks no demonstration was drawn from
AT_LEAST = 7  # of 10: 10 measured (AMD EPYC); a margin for another processor's closed loop


def test_the_committed_pick_and_place_policy_has_todays_recipe_and_solves_held_out_tasks(
    committed,
):
    world, recipe, policy = committed(PICK)
    assert recipe["dagger_rounds"] == world.cloning.dagger_rounds == 2
    assert replays_rollouts(world) and not replays_rollouts(sim.get_world("nav2d"))
    tasks = [world.train_task(seed=s) for s in HELD_OUT]
    solved = sum(t.success for t in world.rollout_batch(tasks, policy))
    assert solved >= AT_LEAST, solved
