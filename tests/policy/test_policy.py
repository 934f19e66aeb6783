import numpy as np
import pytest
import torch

from policy import failing_test_task, finetune, load_policy, save_policy, training_demos
from sim.core import SHIFTS


def test_checkpoint_round_trip_is_bit_exact(nav, nav_policy, tmp_path):
    save_policy(nav_policy, tmp_path / "ckpt")
    back = load_policy(tmp_path / "ckpt", world=nav)
    for (k, a), (k2, b) in zip(
        nav_policy.net.state_dict().items(), back.net.state_dict().items(), strict=True
    ):
        assert k == k2 and torch.equal(a, b)
    obs = nav.demonstrate(nav.train_task()).observations
    assert np.array_equal(nav_policy(obs), back(obs))


def test_base_policy_solves_the_training_distribution(nav, nav_policy):
    wins = sum(nav.rollout(nav.train_task(seed), nav_policy).success for seed in range(10))
    assert wins >= 9


@pytest.mark.parametrize("shift", SHIFTS)
def test_base_policy_fails_on_shifted_tasks(nav, nav_policy, shift):
    for seed in range(3):
        task, rollout = failing_test_task(nav, nav_policy, shift, seed)
        assert task.shift == shift and not rollout.success
        assert nav.demonstrate(task).success  # the expert can do it: the policy is what fails


def test_replay_keeps_what_the_base_policy_could_do(nav, nav_policy):
    """Finetuning on one demonstration alone erases the other training layouts; replaying
    the base policy's own demonstrations in every batch keeps them."""
    known = training_demos(nav)
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    train = [nav.train_task(seed=i) for i in range(1, 9)]

    def solved(policy):
        return sum(t.success for t in nav.rollout_batch(train, policy))

    assert solved(nav_policy) == len(train)
    alone, _ = finetune(nav, nav_policy, [demo] * 5)
    kept, losses = finetune(nav, nav_policy, [demo] * 5, replay=known)
    assert solved(alone) <= len(train) // 2
    assert solved(kept) >= len(train) - 1
    assert np.isfinite(losses).all()


def test_training_demonstrations_are_made_once_per_process(nav):
    first, again = training_demos(nav), training_demos(nav)
    assert first is not again and all(a is b for a, b in zip(first, again, strict=True))
    first.pop()  # the caller's own list
    assert len(training_demos(nav)) == len(again)
