import numpy as np
import pytest
import torch

from policy import (
    augment,
    evaluate,
    failing_test_task,
    finetune,
    load_policy,
    save_policy,
    training_demos,
)
from sim.core import SHIFTS, Feedback, Label, UserError


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


def test_augmentation_rerenders_every_state_and_keeps_actions(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    demo = nav.demonstrate(task)
    slot, concept = task.cause
    values = nav.space.slot(slot).concept(concept).values
    aug = augment(nav, task, demo, Feedback((Label(slot, concept, False, values),)))
    assert len(aug) == len(values) - 1
    seen = {a.scenes[0].obj(slot).value(concept) for a in aug}
    assert seen == set(values) - {task.scene.obj(slot).value(concept)}
    for a in aug:
        assert np.array_equal(a.actions, demo.actions)
        assert all(s.obj(slot).value(concept) in seen for s in a.scenes)
        assert np.array_equal(a.observations, nav.render_batch(a.scenes))


def test_distractor_augmentation_places_it_off_the_path(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "distractor_ti", 0)
    demo = nav.demonstrate(task)
    aug = augment(
        nav, task, demo, Feedback((Label("distractor", "presence", False, ("present", "absent")),))
    )
    places = nav.placements(task, "distractor", demo)
    assert (
        places and len(aug) == 16 * len(places) + 1 - 1
    )  # every look at every place, minus itself, plus absent
    for a in aug:
        d = a.scenes[0].obj("distractor")
        assert not d.present or d.pos in places


def test_tr_feedback_adds_nothing(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_tr", 0)
    demo = nav.demonstrate(task)
    slot, concept = task.cause
    assert augment(nav, task, demo, Feedback((Label(slot, concept, True),))) == []


def test_evaluation_is_seeded(nav, nav_policy):
    task, _ = failing_test_task(nav, nav_policy, "object_ti", 1)
    assert evaluate(nav, nav_policy, task, seed=4) == evaluate(nav, nav_policy, task, seed=4)


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


def test_fresh_tasks_over_training_layouts(nav, nav_policy):
    from sim.nav2d.world import TRAIN_LAYOUTS

    task, _ = failing_test_task(nav, nav_policy, "object_ti", 0)
    same = nav.fresh_tasks(task, 30, seed=2)
    moved = nav.fresh_tasks(task, 30, seed=2, layouts="train")
    assert all(t.scene.agent == task.scene.agent for t in same)
    layouts = {(t.scene.agent[:2], t.scene.obj("goal").pos) for t in moved}
    assert layouts <= set(TRAIN_LAYOUTS) and len(layouts) >= 6
    # the looks are drawn as before: only the positions differ
    for a, b in zip(same, moved, strict=True):
        assert a.scene.obj("goal").values == b.scene.obj("goal").values
    with pytest.raises(UserError, match="layouts"):
        nav.fresh_tasks(task, 3, seed=2, layouts="anywhere")
    score = evaluate(nav, nav_policy, task, seed=2, layouts="train")
    assert score == evaluate(nav, nav_policy, task, seed=2, layouts="train")
