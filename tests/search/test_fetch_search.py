"""The search on FetchPickAndPlace (a closed-loop world, whose counterfactual "succeeds"): with
the committed policy, putting the recoloured object or table back as training had it is a
counterfactual, and the shifted scene itself is not."""

import pytest

from policy import base_policy
from search.lockstep import rollout_lockstep
from sim import get_world
from sim.core import EMPTY, Change, Edit

SEEDS = range(4)  # the undo was a counterfactual on 3 of these 4 (seed 1 fails either way)


@pytest.fixture(scope="module")
def world():
    return get_world("fetch:FetchPickAndPlace-v4")


def test_undoing_the_recolour_is_a_counterfactual(world):
    assert world.counterfactual == "succeeds"
    policy = base_policy(world)
    undone = 0
    for seed in SEEDS:
        task = world.test_task("object_ti", seed)
        slot, concept = task.cause
        was = world.train_task(task.seed).scene.obj(slot).value(concept)
        undo = Edit.of(Change(slot, concept, task.scene.obj(slot).value(concept), was))
        demo = world.demonstrate(task)
        shifted, back = rollout_lockstep(
            world, policy, task.scene, demo, [EMPTY, undo], epsilon=world.epsilon, task=task
        )
        assert not shifted.valid and shifted.dropped_at == world.horizon
        undone += back.valid
    assert undone >= 2
