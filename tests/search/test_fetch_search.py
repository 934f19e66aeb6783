"""The search on FetchPickAndPlace (a closed-loop world, whose counterfactual "succeeds"): with
the committed policy, undoing the shift (the recoloured table or object put back as training
had it, the added block taken away) is a counterfactual, and the shifted scene itself is not."""

import pytest

from policy.base import record_folder
from policy.checkpoint import load_policy
from search.lockstep import rollout_lockstep
from sim import get_world
from sim.core import ABSENT, EMPTY, PRESENCE, PRESENT, Change, Edit

SEEDS = range(4)  # the undo was a counterfactual on 3 of these 4 in each shift (not seed 1)


@pytest.fixture(scope="module")
def world():
    return get_world("fetch:FetchPickAndPlace-v4")


def undo(world, task) -> Edit:
    slot, concept = task.cause
    if concept == PRESENCE:
        return Edit.of(Change(slot, PRESENCE, PRESENT, ABSENT))
    was = world.train_task(task.seed).scene.obj(slot).value(concept)
    return Edit.of(Change(slot, concept, task.scene.obj(slot).value(concept), was))


@pytest.mark.parametrize("shift", ["object_ti", "distractor_ti"])
def test_undoing_the_shift_is_a_counterfactual(world, shift):
    assert world.counterfactual == "succeeds"
    policy = load_policy(record_folder(world), world=world)  # the committed one
    undone = 0
    for seed in SEEDS:
        task = world.test_task(shift, seed)
        demo = world.demonstrate(task)
        shifted, back = rollout_lockstep(
            world,
            policy,
            task.scene,
            demo,
            [EMPTY, undo(world, task)],
            epsilon=world.epsilon,
            task=task,
        )
        assert not shifted.valid and shifted.dropped_at == world.horizon
        undone += back.valid
    assert undone >= 2
